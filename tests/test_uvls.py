"""The UVLS baseline: relays driven by hand-built voltage sequences, then whole episodes.

The relays are first fed synthetic observations of the ieee39_fidvr layout (voltages at the
8 observed buses, then the remaining load at the 3 action buses 504/507/518), with the
remaining load updated as the env would. Then they run the study's task on the built-in
case, shortened to 6 s as in tests/test_env.py, in one compiled rollout shared by the tests
(no control = the same relays with every fraction zero, so nothing recompiles).
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from baselines.uvls import UvlsParams, check_params, uvls_policy
from jaxgrid.env import EnvConfig, EnvParams, LoadSheddingEnv
from jaxgrid.episode import play_tasks
from jaxgrid.simulate import FaultEvent, make_task, stack_tasks

FRACTION_TOL = 1e-6  # float32 fractions of 0.2 after a subtraction or two


@pytest.fixture(scope="module")
def study(ieee39):
    return ieee39


@pytest.fixture(scope="module")
def env(study):
    return study.env(episode=6.0)


@pytest.fixture(scope="module")
def relay(env):
    policy_apply, params, carry = uvls_policy(env)
    return jax.jit(policy_apply), params, carry


def drive(env, relay, vm_action, params=None, left0=None, history_env=None):
    """Actions (T, 3) of the relays fed voltages vm_action (T, 3) at the action buses.

    Other observed buses sit at 1.0 p.u.; the remaining load starts at `left0` (default 1)
    and drops by what the env would shed (the clipped request), as in `LoadSheddingEnv.step`.
    """
    apply, default, carry = relay
    params = default if params is None else params
    use = history_env or env
    slot = [list(use.config.observed_buses).index(b) for b in use.config.action_buses]
    left = np.ones(3, np.float32) if left0 is None else np.asarray(left0, np.float32)
    stacked = None
    actions = []
    for row in np.asarray(vm_action, np.float32):
        vm = np.ones(len(use.config.observed_buses), np.float32)
        vm[slot] = row
        obs = np.concatenate([vm, left])
        stacked = np.tile(obs, use.config.history) if stacked is None else \
            np.concatenate([stacked[use.obs_size:], obs])
        action, carry = apply(params, jnp.asarray(stacked), carry, None)
        action = np.asarray(action)
        assert np.all((action <= 0) & (action >= -0.2 - FRACTION_TOL)), \
            f"action {action} outside the env's range [-0.2, 0]"
        left = left - np.minimum(-np.clip(action, -0.2, 0.0), left)
        actions.append(action)
    return np.array(actions), carry


def shed_steps(actions, bus=0):
    """{step index: amount shed} at one action bus."""
    return {int(k): round(float(-actions[k, bus]), 6) for k in np.flatnonzero(actions[:, bus])}


def test_each_stage_trips_once_at_its_step(env, relay):
    """V = 0.65 at 504 from the first observation: stages at the 4th, 5th, 15th low sample."""
    vm = np.ones((30, 3))
    vm[:, 0] = 0.65
    actions, carry = drive(env, relay, vm)
    assert shed_steps(actions) == {3: 0.2, 4: 0.2, 14: 0.2}, \
        "0.33 s -> 4th, 0.5 s -> 5th, 1.5 s -> 15th observation at 0.1 s; latched after"
    assert not np.any(actions[:, 1:]), "healthy buses shed nothing"
    assert np.asarray(carry.tripped).tolist() == [[True] * 3, [False] * 3, [False] * 3], \
        "latched: each stage once, only at 504"


def test_only_stages_whose_level_is_crossed_trip(env, relay):
    vm = np.ones((30, 3))
    vm[:, 1] = 0.85  # below 0.9 only: stage 3
    vm[:, 2] = 0.75  # below 0.8 and 0.9: stages 2 and 3
    actions, _ = drive(env, relay, vm)
    assert shed_steps(actions, 1) == {14: 0.2}, "0.85 p.u.: stage 3 alone"
    assert shed_steps(actions, 2) == {4: 0.2, 14: 0.2}, "0.75 p.u.: stages 2 and 3"
    assert not np.any(actions[:, 0]), "1.0 p.u.: nothing"


def test_timer_resets_when_voltage_recovers(env, relay):
    """0.75 p.u. for 4 samples, one sample at 0.95, then low again: stage 2 restarts its count."""
    vm = np.ones((12, 3))
    vm[:4, 0] = 0.75
    vm[4, 0] = 0.95
    vm[5:, 0] = 0.75
    actions, _ = drive(env, relay, vm)
    assert shed_steps(actions) == {9: 0.2}, "5 consecutive low samples after the reset (5..9)"


def test_voltage_at_the_level_does_not_pick_up(env, relay):
    vm = np.full((20, 3), 0.9, np.float32)  # the level itself is not "below"
    actions, _ = drive(env, relay, vm)
    assert not np.any(actions), "a stage counts only strictly below its level"


def test_two_stages_tripping_together_shed_both_over_two_steps(env, relay):
    """One sample at 0.75 then 0.65: stage 1 (4th < 0.7) and stage 2 (5th < 0.8) trip at step 4;
    the env takes at most 0.2 a step, so the second 0.2 is carried to step 5."""
    vm = np.full((20, 3), 1.0)
    vm[0, 0] = 0.75
    vm[1:, 0] = 0.65
    actions, carry = drive(env, relay, vm)
    assert shed_steps(actions) == {4: 0.2, 5: 0.2, 14: 0.2}, "stage 2's 0.2 carried to step 5"
    assert float(np.sum(-actions[:, 0])) == pytest.approx(0.6, abs=FRACTION_TOL), \
        "every tripped stage sheds its full fraction"
    assert float(carry.owed[0]) == 0.0, "nothing left owed"


def test_remainder_beyond_the_load_left_is_dropped(env, relay):
    """Only 0.1 left at 504: the relay asks for 0.1 once, never for an empty bus."""
    vm = np.ones((20, 3))
    vm[:, 0] = 0.65
    actions, carry = drive(env, relay, vm, left0=[0.1, 1.0, 1.0])
    assert shed_steps(actions) == {3: 0.1}, "capped at the load left, no request at an empty bus"
    assert float(carry.owed[0]) == 0.0, "the remainder that cannot be shed is dropped"


def test_relay_reads_the_newest_of_stacked_observations(study, env, relay):
    stacked = study.env(episode=6.0, history=3)
    apply, params, carry = uvls_policy(stacked)
    vm = np.ones((10, 3))
    vm[:, 0] = 0.65
    actions, _ = drive(stacked, (jax.jit(apply), params, carry), vm, history_env=stacked)
    assert shed_steps(actions) == {3: 0.2, 4: 0.2}, "same trips as with one observation"


@pytest.mark.parametrize("delay, trip_sample", [
    (0.0, 1), (0.05, 1), (0.1, 1), (0.10000001, 1), (0.101, 2), (0.3, 3), (0.33, 4), (0.5, 5),
    (1.5, 15)])
def test_delay_rounds_up_to_whole_control_steps(env, delay, trip_sample):
    """The stage trips on the first sample n with n · 0.1 s >= delay (to 1e-4 of a step)."""
    apply, params, carry = uvls_policy(env, UvlsParams(levels=[0.9], delays=[delay],
                                                       fractions=[0.2]))
    vm = np.full((20, 3), 0.5)
    actions, _ = drive(env, (jax.jit(apply), params, carry), vm)
    assert shed_steps(actions) == {trip_sample - 1: 0.2}, f"delay {delay} s"


def test_zero_fractions_never_shed(env, relay):
    none = check_params(UvlsParams(fractions=[0.0, 0.0, 0.0]))
    actions, _ = drive(env, relay, np.full((20, 3), 0.5), params=none)
    assert not np.any(actions), "stages trip but shed 0"


@pytest.mark.parametrize("settings, message", [
    ({"levels": [0.7, 0.8]}, "stage counts differ"),
    ({"levels": [0.7, 0.8, 0.0]}, r"UvlsParams.levels = .*\(0, 1.5\]"),
    ({"delays": [0.33, -0.5, 1.5]}, r"UvlsParams.delays = .*\[0, inf\)"),
    ({"delays": [0.33, float("nan"), 1.5]}, r"UvlsParams.delays"),
    ({"fractions": [0.2, 1.2, 0.2]}, r"UvlsParams.fractions = .*\[0, 1\]"),
    ({"fractions": [0.5, 0.5, 0.5]}, r"UvlsParams.fractions = .*sum 1.5"),
    ({"step_limit": 0.0}, r"UvlsParams.step_limit = .*\(0, 1\]"),
    ({"levels": [[0.7, 0.8, 0.9]]}, r"UvlsParams.levels = .*shape \(1, 3\)"),
    ({"levels": "low"}, r"UvlsParams.levels = 'low' \(str\)"),
])
def test_out_of_range_settings_are_named(env, settings, message):
    with pytest.raises(ValueError, match=message):
        uvls_policy(env, UvlsParams(**settings))


def test_action_bus_must_be_observed_and_its_load_fraction_too(study):
    config = EnvConfig(observed_buses=(4, 504, 7, 507), action_buses=(504, 507, 518))
    blind = LoadSheddingEnv(study.point(0), config)
    with pytest.raises(ValueError, match=r"action buses \[518\] are not among observed_buses"):
        uvls_policy(blind)
    with pytest.raises(ValueError, match="include_action_status = true"):
        uvls_policy(study.env(include_action_status=False))


# --------------------------------------------------------------------------- #
# Episodes on ieee39_fidvr
# --------------------------------------------------------------------------- #

@pytest.fixture(scope="module")
def episodes(study, env):
    """UVLS and no control (fractions 0) on [no fault, bus-4 0.02 s, bus-4 0.08 s (FIDVR)]."""
    grid = study.point(0)
    faults = [None, FaultEvent(4, 1.0, 0.02), FaultEvent(4, 1.0, 0.08)]
    batch = stack_tasks([make_task(grid, f) for f in faults])
    policy_apply, params, carry = uvls_policy(env)
    off = params.replace(fractions=np.zeros_like(params.fractions))
    run = jax.jit(functools.partial(play_tasks, env), static_argnums=(0, 6))
    return {name: jax.tree.map(np.asarray, run(policy_apply, p, batch, EnvParams(), grid, carry,
                                               True))
            for name, p in (("uvls", params), ("none", off))}


def test_uvls_on_the_fidvr_task(episodes, study, env):
    uvls, none = episodes["uvls"], episodes["none"]
    print("\ntasks: [no fault, bus 4 0.02 s, bus 4 0.08 s]")
    for name, out in (("no control", none), ("UVLS", uvls)):
        print(f"{name:>10}: reward {out['reward'].round(2)}, shed_pu {out['shed_pu'].round(4)}, "
              f"recovered {out['recovered'].tolist()}, steps {out['steps'].tolist()}")
    for k in range(3):
        steps = np.flatnonzero(uvls["shed_step_pu"][k])
        print(f"  task {k}: UVLS sheds {uvls['shed_step_pu'][k][steps].round(4).tolist()} p.u. "
              f"at t = {(steps * env.config.agent_dt).round(1).tolist()} s")
    assert none["recovered"].tolist() == [True, True, False], "the no-control baseline of test_env"
    assert none["shed_pu"].tolist() == [0.0, 0.0, 0.0]
    assert uvls["shed_pu"][0] == 0.0 and uvls["reward"][0] == pytest.approx(0.0, abs=1e-6), \
        "no fault: the voltages stay high and no relay trips"
    assert uvls["shed_pu"][2] > 0.0, "FIDVR: the relays shed load"
    p0 = float(np.sum(np.asarray(study.point(0).load_p0)[env.action_slots]))
    assert np.all(uvls["shed_pu"] <= 0.6 * p0 * (1 + 1e-5)), "each stage sheds 20 % at most once"
