"""The PARS study's published networks as a controller ("rlgc:FILE", `baselines.rlgc`).

The controller's actions against a float64 NumPy reading of the equations of
../shared/reference/rlgc-policies/README.md, written out here apart from the library's
code, on random weights (every kind, small sizes) and on every shipped file; the published
layouts against the PNNL files they come from; the training log; bad files and layouts.

Tolerance: the controller runs in float32, as the simulation; the reference in float64 on the
same (float32) observations. The float32 mean and std err by 2^-24 ≈ 6e-8 relative; with
obs_std >= 0.1 (every shipped file) a normalised input errs by <= 1e-6, and each float32 sum
of up to 218 products (the 300-bus LSTM's gates) with |w| <= 25 adds rounding of the same
order. tanh and σ do not amplify (slopes <= 1), so the errors add up over the layers without
growth: measured, at most 5e-6 on the action (the 300-bus LSTM), 1e-7 on the 39-bus files
and the random ones. `ATOL` = 2e-5 on the action (p.u. of the initial load per step) is 4
times that and 1e-4 of the action range [−0.2, 0].
"""
from __future__ import annotations

import dataclasses
import json
import shutil
import types

import jax
import numpy as np
import pytest

from baselines.controllers import load
from baselines.rlgc import (LOG_TASKS, RlgcNetwork, networks_of_size, read_policy,
                            rlgc_apply, training_log)
from baselines.rlgc_layouts import IEEE39, IEEE300
from jaxgrid.env import EnvConfig
from jaxgrid.io.dyr import read_dyr
from jaxgrid.study.pnnl import read_task_config
from jaxgrid.io.raw import read_raw
from jaxgrid.study import bus_number
from jaxgrid.study.names import bus_table
from conftest import REPO, SHARED_CASES

POLICIES = REPO.parent / "shared" / "reference" / "rlgc-policies"
SHIPPED = sorted(POLICIES.glob("**/*.npz"))
V5 = POLICIES / "IEEE39_load_shedding/39-Bus_ARS/Seed/LSTM/ars_39_continuous_9cases_v5"
ATOL = 2e-5  # on the action, p.u. of the initial load (module docstring)

# an environment observing more buses than the 39-bus networks, in another order, and acting
# on the action buses in another order: the controller picks and places by bus number
STUDY_39 = EnvConfig(observed_buses=(4, 504, 7, 507, 8, 508, 18, 518),
                     action_buses=(518, 504, 507))


def reference_actions(kind, hidden, n_act, w, mean, std, inputs):
    """Actions (steps, n_act) of a published network on its input sequence (steps, n_in),
    float64, read from the README: x = (ob − mean)/(std + 1e-8); linear tanh(w x); FNN and
    the LSTM's dense part: for each pair (a, b) of [.., n_act] the next a·b entries are a
    (b, a) matrix, tanh after each; LSTM: 4 (n_in + H, H) gates f, i, c, o on z = [h, x];
    a = −0.2 + (t + 1)/2 · 0.2."""
    sigmoid = lambda u: 1.0 / (1.0 + np.exp(-u))  # noqa: E731
    n_in = mean.size

    def dense(flat, sizes, y):
        start = 0
        for a, b in zip(sizes, sizes[1:]):
            y = np.tanh(flat[start:start + a * b].reshape(b, a) @ y)
            start += a * b
        return y

    h = c = np.zeros(hidden[0]) if kind == "lstm" else None
    actions = []
    for ob in inputs:
        x = (ob - mean) / (std + 1e-8)
        if kind == "linear":
            t = np.tanh(w @ x)
        elif kind == "fnn":
            t = dense(w, [n_in, *hidden, n_act], x)
        else:
            size = (n_in + hidden[0]) * hidden[0]
            wf, wi, wc, wo = (w[k * size:(k + 1) * size].reshape(n_in + hidden[0], hidden[0])
                              for k in range(4))
            z = np.concatenate([h, x])
            c = sigmoid(z @ wf) * c + sigmoid(z @ wi) * np.tanh(z @ wc)
            h = sigmoid(z @ wo) * np.tanh(c)
            t = dense(w[4 * size:], [hidden[0], hidden[1], n_act], h)
        actions.append(-0.2 + (t + 1.0) / 2.0 * 0.2)
    return np.array(actions)


def fake_env(config: EnvConfig):
    """What `rlgc_apply` reads of an environment, without building a grid."""
    n_obs = len(config.observed_buses) + len(config.action_buses)
    return types.SimpleNamespace(config=config, action_slots=np.arange(len(config.action_buses)),
                                 obs_size=n_obs)


def run_both(path, config: EnvConfig, steps: int, seed: int = 0):
    """(controller actions, reference actions), both (steps, env actions), of the file at
    `path` on random environment observations (voltages 0.6-1.1 p.u., fractions 0.4-1),
    stacked as the environment stacks them (reset: copies of the first; newest last)."""
    policy, params = read_policy(path)
    env = fake_env(config)
    apply = jax.jit(rlgc_apply(policy, env))
    rng = np.random.default_rng(seed)
    n_v, n_a = len(config.observed_buses), len(config.action_buses)
    frames = np.concatenate([rng.uniform(0.6, 1.1, (steps, n_v)),
                             rng.uniform(0.4, 1.0, (steps, n_a))], axis=1).astype(np.float32)
    stack = np.repeat(frames[:1], config.history, axis=0)
    carry, ours, inputs = policy.network.initial_carry(), [], []
    for frame in frames:
        stack = np.concatenate([stack[1:], frame[None]])
        action, carry = apply(params, stack.reshape(-1), carry, None)
        ours.append(np.asarray(action))
        voltage = dict(zip(config.observed_buses, stack[:, :n_v].T))
        fraction = dict(zip(config.action_buses, stack[:, n_v:].T))
        layout = policy.layout
        columns = [voltage[b] for b in layout.voltage_buses] + \
            [fraction[b] for b in layout.action_buses]
        inputs.append(np.stack(columns, axis=1).reshape(-1).astype(np.float64))  # oldest first
    w, mean, std = (np.asarray(a, np.float64)
                    for a in np.load(path, allow_pickle=True)["arr_0"][:3])
    reference = reference_actions(policy.network.kind, policy.network.hidden,
                                  len(policy.layout.action_buses), w, mean, std,
                                  np.array(inputs))
    order = [policy.layout.action_buses.index(b) for b in config.action_buses]
    return np.array(ours), reference[:, order]


def write_policy(path, w, mean, std):
    """A file in the published format: arr_0 an object array [w, obs_mean, obs_std]."""
    saved = np.empty(3, object)
    saved[0], saved[1], saved[2] = w, mean, std
    np.savez(path, saved)
    return path


@pytest.mark.parametrize("kind, n_in, hidden", [("linear", 14, ()), ("fnn", 14, (5, 5)),
                                                ("lstm", 7, (4, 4))])
def test_random_networks_equal_the_numpy_reading(tmp_path, kind, n_in, hidden):
    rng = np.random.default_rng(1)
    network = RlgcNetwork(kind, n_in, 3, hidden)
    w = rng.normal(0, 0.3, (3, n_in) if kind == "linear" else network.size)
    path = write_policy(tmp_path / "policy_plus1.npz", w, rng.normal(0.9, 0.1, n_in),
                        rng.uniform(0.1, 0.4, n_in))
    policy, _ = read_policy(path)
    assert (policy.network, policy.layout, policy.history) == (network, IEEE39, n_in // 7)
    config = dataclasses.replace(STUDY_39, history=n_in // 7)
    ours, reference = run_both(path, config, steps=6)
    print(f"\n{kind}: largest |difference| {np.abs(ours - reference).max():.1e}")
    np.testing.assert_allclose(ours, reference, atol=ATOL, rtol=0)
    assert np.ptp(reference) > 0.01, "the inputs move the actions"


EXPECTED = {"LSTM": ("lstm", (32, 32), 1), "FNN": ("fnn", (32, 32), 10),
            "Linear": ("linear", (), 10), "39-Bus_ARS": ("lstm", (32, 32), 1),
            "300-bus-ARS": ("lstm", (64, 64), 1)}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: "/".join(p.parts[-3:-1]))
def test_shipped_files_equal_the_numpy_reading(path):
    policy, _ = read_policy(path)
    folder = path.parts[-3] if path.parts[-3] in EXPECTED else path.parts[-2]
    kind, hidden, history = EXPECTED[folder]
    assert (policy.network.kind, policy.network.hidden, policy.history) == \
        (kind, hidden, history)
    if policy.layout == IEEE300:  # as studies/ieee300_pnnl.toml: 108 + 46 observed
        config = EnvConfig(observed_buses=IEEE300.voltage_buses + IEEE300.action_buses,
                           action_buses=IEEE300.action_buses)
    else:
        config = dataclasses.replace(STUDY_39, history=history)
    ours, reference = run_both(path, config, steps=5)
    print(f"\n{folder}: largest |difference| {np.abs(ours - reference).max():.1e}")
    np.testing.assert_allclose(ours, reference, atol=ATOL, rtol=0)


def test_the_300_bus_layout_is_the_zone_1_buses_from_60_kv_and_the_task_s_action_buses():
    raw = read_raw(SHARED_CASES / "ieee300/IEEE300Bus_modified_noHVDC_v2.raw")
    zone1 = [int(n) for n, z, kv in zip(raw.buses.number, raw.buses.zone, raw.buses.base_kv)
             if z == 1 and kv >= 60.0]
    assert IEEE300.voltage_buses == tuple(zone1) and len(zone1) == 108
    table = bus_table(raw, read_dyr(SHARED_CASES / "ieee300/IEEE300_dyn_cmld_zone1.dyr"))
    task = read_task_config(SHARED_CASES / "ieee300/IEEE300_RL_loadShedding_zone1_continuous_"
                                           "LSTM_new_lessfaultbuses_moreActionBuses_"
                                           "multipfcases.json")
    assert IEEE300.action_buses == tuple(bus_number(n, table, task.source, "actionScopeAry")
                                         for n in task.action)


def test_the_39_bus_layout_is_the_gridpack_task_file_s():
    task = read_task_config(SHARED_CASES / "ieee39/IEEE39_RL_loadShedding_3motor_continuous_"
                                           "reducedActionRange_gp.json")
    number = lambda names: tuple(int(n.removeprefix("Bus")) for n in names)  # noqa: E731
    assert (IEEE39.voltage_buses, IEEE39.action_buses) == (number(task.observed),
                                                           number(task.action))


def test_the_training_log_row_of_the_file_s_iteration():
    log = training_log(V5 / "policy_plus500.npz")
    assert log.iteration == 500 and list(log.rewards) == list(LOG_TASKS)
    assert log.reward(4, 0.05, 1.0) == pytest.approx(-247.4614212652558)
    assert log.reward(21, 0.08, 1.0) == pytest.approx(-24.21864051753935)
    assert log.reward(4, 0.05, 0.5) is None and log.reward(5, 0.05, 1.0) is None
    assert training_log(SHIPPED[0]) is None, "the 300-bus file has no log"


def test_the_controller_registry_reads_rlgc_files():
    spec = f"rlgc:{V5 / 'policy_plus500.npz'}"
    study = types.SimpleNamespace(name="fake", env=lambda history: fake_env(
        dataclasses.replace(STUDY_39, history=history)))  # what a loader reads of a study
    controller = load(spec, study)
    assert controller.history == 1 and controller.env.config.history == 1
    action, carry = controller.apply(controller.params, np.full(11, 0.95, np.float32),
                                     controller.carry, None)
    assert action.shape == (3,) and ((-0.2 <= action) & (action <= 0.0)).all()
    assert carry[0].shape == (32,)


@pytest.fixture(scope="module")
def lstm_file(tmp_path_factory):
    """A small LSTM file of the 39-bus layout, in a folder of its own."""
    rng = np.random.default_rng(2)
    folder = tmp_path_factory.mktemp("lstm")
    return write_policy(folder / "policy_plus3.npz",
                        rng.normal(0, 1, RlgcNetwork("lstm", 7, 3, (4, 4)).size),
                        np.ones(7), np.ones(7))


@pytest.mark.parametrize("arrays, message", [
    ((np.zeros(100), np.zeros(7), np.ones(7)),
     r"w of shape \(100,\) with 7 inputs fits none of the published layouts"),
    ((np.zeros((3, 8)), np.zeros(8), np.ones(8)), r"w of shape \(3, 8\) with 8 inputs fits none"),
    ((np.zeros(10), np.zeros(7), np.ones(6)), r"obs_mean \(7,\) and obs_std \(6,\)"),
    ((np.zeros(10), np.zeros(7), -np.ones(7)), r"obs_std >= 0"),
])
def test_files_whose_sizes_fit_nothing_are_refused_by_name(tmp_path, arrays, message):
    path = write_policy(tmp_path / "bad.npz", *arrays)
    with pytest.raises(ValueError, match=f"{path}: .*{message}"):
        read_policy(path)


def test_files_not_in_the_format_are_refused_by_name(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("not an npz")
    with pytest.raises(ValueError, match=f"{text}: not a published policy file"):
        read_policy(text)
    short = tmp_path / "short.npz"
    np.savez(short, np.zeros(2))
    with pytest.raises(ValueError, match=r"arr_0 has shape \(2,\)"):
        read_policy(short)
    named = tmp_path / "named.npz"
    np.savez(named, weights=np.zeros(2))
    with pytest.raises(ValueError, match=f"{named}: not a published policy file .*arr_0"):
        read_policy(named)
    with pytest.raises(ValueError, match=f"{tmp_path / 'none.npz'}: no such file"):
        read_policy(tmp_path / "none.npz")


def test_a_params_json_that_names_another_network_is_refused(tmp_path, lstm_file):
    copy = shutil.copy(lstm_file, tmp_path / "policy_plus3.npz")
    (tmp_path / "params.json").write_text(json.dumps(
        {"policy_type": "nonlinear", "policy_network_size": [4, 4]}))
    with pytest.raises(ValueError, match=r"fits a lstm network \(4, 4\), but .*params.json "
                                         r"says policy_type 'nonlinear'"):
        read_policy(copy)


@pytest.mark.parametrize("config, message", [
    (EnvConfig(observed_buses=(504, 507, 518), action_buses=(504, 507, 518)),
     r"observes the voltage at buses \[508\], which this study's environment does not; it "
     r"observes \[504, 507, 518\]"),
    (EnvConfig(observed_buses=(504, 507, 508, 518), action_buses=(504, 507)),
     r"sheds at buses \[518\], which this study's environment does not; it acts on "
     r"\[504, 507\]"),
    (EnvConfig(observed_buses=(504, 507, 508, 518), action_buses=(504, 507, 518),
               include_action_status=False), "needs include_action_status = true"),
    (EnvConfig(observed_buses=(504, 507, 508, 518), action_buses=(504, 507, 518), history=10),
     "stacks 1 observations; the environment 10"),
])
def test_environments_without_the_layout_s_buses_are_refused_by_name(lstm_file, config,
                                                                       message):
    policy, _ = read_policy(lstm_file)
    with pytest.raises(ValueError, match=f"{lstm_file}.*{message}"):
        rlgc_apply(policy, fake_env(config))


def test_a_log_without_the_file_s_iteration_is_refused(tmp_path):
    shutil.copy(V5 / "log.txt", tmp_path / "log.txt")
    with pytest.raises(ValueError, match=r"log.txt: no row of iteration 7 \(policy_plus7.npz\)"):
        training_log(tmp_path / "policy_plus7.npz")


def test_only_equal_width_networks_of_the_given_sizes_fit():
    assert networks_of_size((6112,), 7, 3) == [RlgcNetwork("lstm", 7, 3, (32, 32))]
    assert networks_of_size((3360,), 70, 3) == [RlgcNetwork("fnn", 70, 3, (32, 32))]
    assert networks_of_size((3, 70), 70, 3) == [RlgcNetwork("linear", 70, 3)]
    assert networks_of_size((3361,), 70, 3) == [] and networks_of_size((2, 2, 2), 7, 3) == []
