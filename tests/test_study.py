"""Studies as data: built from files or built-ins, saved and read back, operating points as
data of one compiled program, and bad input named.

The PNNL 39-bus study is read from its own files (base case and two baseCases load levels as
operating points, strict mode with its ACMTBLU1 loads) once for the module, with 3 s
episodes (the fault at 1 s, no recovery judgement needed for these checks).
"""
from __future__ import annotations

import dataclasses
import json
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest

from baselines.controllers import no_control
from jaxgrid.case import SLACK, at_load_level
from jaxgrid.env import EnvParams
from jaxgrid.io.raw import read_raw
from jaxgrid.powerflow import PowerFlowError, solve, with_reactive_room
from jaxgrid.problem import _points_play, at_point, play_specs, stratified_sampler
from jaxgrid.study import builtin, from_files, read_study, write_study
from jaxgrid.tasks import TaskSet, TaskSpec

BASE = "ieee39/IEEE39bus_multiloads_xfmr4_smallX_v30.raw"
POINTS = [BASE, "ieee39/baseCases/IEEE39bus_multiloads_xfmr4_smallX_v30_4load_perc90.raw",
          "ieee39/baseCases/IEEE39bus_multiloads_xfmr4_smallX_v30_4load_perc110.raw"]
DYR = "ieee39/IEEE39bus_3AC.dyr"
TASK = "ieee39/IEEE39_RL_loadShedding_3motor_continuous.json"
SIM = "ieee39/IEEE39_dyn_config.json"
EPISODE = 3.0  # s
REPO = Path(__file__).parent.parent
# Per-point runs against one multi-point batch: the same float32 arithmetic per rollout,
# vmapped in another layout (XLA may block the network products differently).
BATCH_RTOL = 1e-4


@pytest.fixture(scope="module")
def pnnl39(shared_cases):
    return from_files([shared_cases / p for p in POINTS], shared_cases / DYR,
                      shared_cases / TASK, shared_cases / SIM, env={"episode": EPISODE})


def test_pnnl_39_bus_study_from_its_files(pnnl39, shared_cases):
    study = pnnl39
    assert study.name == "IEEE39_FIDVR_LoadShedding_Continuous_Action"
    assert [p.label for p in study.points] == [(shared_cases / p).stem for p in POINTS]
    config = study.config
    assert config.observed_buses == (4, 504, 7, 507, 8, 508, 18, 518)
    assert config.action_buses == (504, 507, 518)
    assert (config.dt, config.agent_dt, config.history) == (0.002, 0.1, 10), \
        "step from the simulation JSON, control step and history from the task JSON"
    assert study.params == EnvParams(action_low=-1.0), "the 39-bus values, range [-1, 0]"
    assert study.task_set("train") == TaskSet((4,), (0.0, 0.05, 0.08), (0.05,))
    assert len(study.tasks("train")) == 9, "1 bus x 3 durations x 3 operating points"
    assert jax.tree.leaves(study.models)[0].shape[0] == 3
    assert any("actionLevels" in note for note in study.notes)
    # the stacked models carry each point's own loads: at the action buses, the load each
    # RAW file gives (MW), not the base case's
    env = study.env()
    for k, path in enumerate(POINTS):
        case = read_raw(shared_cases / path)
        mw = [sum(p for b, p, on in zip(case.buses.number[case.loads.bus],
                                        case.loads.p_power, case.loads.in_service)
                  if b == bus and on) * case.base_mva for bus in config.action_buses]
        have = np.asarray(study.models.load_p0)[k, env.action_slots] * study.base_mva
        assert have == pytest.approx(mw, rel=1e-6), path  # float32 model arrays


@pytest.fixture(scope="module")
def uncontrolled(pnnl39):
    """Every task of a 3-point set in one call (vmapped over the points), and the same tasks
    point by point (`play_specs` plays one point without that vmap), in the jitted rollout
    `play_specs` caches, which takes the grid model as an argument."""
    study = pnnl39
    env = study.env()
    apply, params, carry = no_control(env)
    specs = TaskSet((4, 15), (0.05, 0.08)).specs(study.n_points)
    ordered, batch = play_specs(study, env, apply, params, specs, carry)
    per_point = [play_specs(study, env, apply, params,
                            [s for s in ordered if s.operating_point == k], carry)[1]
                 for k in range(study.n_points)]
    return ordered, batch, per_point, _points_play(env, apply, False)


def test_multi_point_batch_equals_per_point_runs(uncontrolled):
    ordered, batch, per_point, _ = uncontrolled
    assert [s.operating_point for s in ordered] == [0] * 4 + [1] * 4 + [2] * 4
    for k, out in enumerate(per_point):
        for key in ("reward", "steps", "recovered"):
            np.testing.assert_allclose(np.asarray(out[key]), batch[key][4 * k:4 * k + 4],
                                       rtol=BATCH_RTOL, err_msg=key)
    rewards = batch["reward"].reshape(3, 4)
    assert np.ptp(rewards, axis=0).max() > 1.0, "the operating points differ"


def test_three_operating_points_one_compilation(uncontrolled):
    *_, run = uncontrolled
    assert run._cache_size() == 2, "the 3-point batch, and one rollout for every point"


def test_pars_iteration_compiles_once_across_operating_points(pnnl39):
    from ars.pars import ParsConfig, init_state
    from ars.train import TrainConfig, make_trainer
    from jaxgrid.problem import training_problem

    # the iteration of `whole_episodes` below: its 2-task program is compiled once per run
    config = ParsConfig(directions=2, top=1, tasks_per_iteration=2)
    problem = training_problem(pnnl39, "linear", history=1, episode=0.5)
    trainer = make_trainer(problem, TrainConfig("linear", (), config))
    state = init_state(trainer.policy, config)
    for point in range(pnnl39.n_points):
        tasks = pnnl39.batch([TaskSpec(4, 0.05, 1.0, point), TaskSpec(15, 0.08, 1.0, point)])
        state, metrics = trainer.iteration(state, tasks, problem.data)
        assert np.isfinite(float(metrics["reward_mean"]))
    assert trainer.iteration.compiled._cache_size() == 1, "none per operating point"


def _regrouping_iteration(study, task_batch, compact_after):
    """(θ (n,), env steps) after one PARS iteration of a linear policy, N = 2, on two tasks
    at two operating points, 0.5-s episodes."""
    from ars.pars import ParsConfig, init_state
    from ars.train import TrainConfig, make_trainer
    from jaxgrid.problem import training_problem

    problem = training_problem(study, "linear", history=1, episode=0.5)
    tasks = study.batch([TaskSpec(4, 0.05, 0.1, 0), TaskSpec(15, 0.08, 0.1, 2)])
    config = ParsConfig(directions=2, top=1, tasks_per_iteration=2, task_batch=task_batch,
                        compact_after=compact_after, compact_chunks=3)
    trainer = make_trainer(problem, TrainConfig("linear", (), config))
    state, metrics = trainer.iteration(init_state(trainer.policy, config), tasks, problem.data)
    return np.asarray(state.theta), float(metrics["env_steps"])


@pytest.fixture(scope="module")
def whole_episodes(pnnl39):
    """The iteration of whole episodes, both tasks in one batch."""
    return _regrouping_iteration(pnnl39, None, None)


@pytest.mark.parametrize("task_batch", [1, None])
def test_regrouped_grid_episodes_equal_whole_ones(pnnl39, whole_episodes, task_batch):
    """`PointEpisode` in two parts (`ParsConfig.compact_after`): episodes regrouped after 2
    agent steps, with one task per batch (the chunk shares it) and with two tasks at two
    operating points (each rollout gathers its model), give the iteration of whole
    episodes: the same steps and θ to float32 rounding (the chunks and the task batches
    are other batch sizes)."""
    whole, whole_steps = whole_episodes
    split, split_steps = _regrouping_iteration(pnnl39, task_batch, 2)
    assert split_steps == whole_steps == 2 * 2 * 2 * 5
    np.testing.assert_allclose(split, whole, rtol=1e-5, atol=1e-5)


def test_at_point_selects_inside_jit(pnnl39):
    pick = jax.jit(lambda models, k: at_point(models, k).load_p0)
    for k in range(3):
        np.testing.assert_array_equal(np.asarray(pick(pnnl39.models, k)),
                                      np.asarray(pnnl39.point(k).load_p0))
    assert pick._cache_size() == 1


def test_study_file_round_trip_gives_the_identical_definition(pnnl39, tmp_path):
    path = tmp_path / "study.toml"
    write_study(pnnl39, path)
    again = read_study(path)
    assert again.definition == pnnl39.definition
    for a, b in zip(jax.tree.leaves(again.models), jax.tree.leaves(pnnl39.models)):
        np.testing.assert_array_equal(a, b)
    study = builtin("ieee39_fidvr", (0.9, 1.0), name="mine", params={"c_shed": 50.0},
                    env={"history": 3, "recovery_buses": (4, 504), "sweeps": 3},
                    tasks={"test": {"fault_buses": (4, 5), "operating_points": (1,)},
                           "extra": {"fault_buses": (16,), "fault_durations": (0.1,)}})
    write_study(study, path)
    assert read_study(path).definition == study.definition
    assert study.task_set("test").fault_durations == (0.02, 0.05, 0.08, 0.1), "kept"


def test_built_in_study_is_the_case_as_before(ieee39):
    from jaxgrid.cases import load

    study, case = ieee39, load("ieee39_fidvr")
    assert (study.config.observed_buses, study.config.action_buses, study.config.dt) == (
        case.observed_buses, case.action_buses, case.dt)
    assert [len(study.tasks(s)) for s in ("train", "test")] == [9, 120]
    assert study.params == EnvParams()


def test_stratified_sampler_draws_k_buses_by_k_durations():
    tasks = TaskSet((4, 15, 21, 16), (0.0, 0.05, 0.08), (0.5, 1.0))
    specs = tasks.specs(5)
    sample = jax.jit(stratified_sampler(tasks, 5, 9))
    for seed in range(5):
        chosen = [specs[int(i)] for i in sample(jax.random.PRNGKey(seed))]
        pairs = {(s.fault_bus, s.fault_duration) for s in chosen}
        assert len(pairs) == 9 and len({b for b, _ in pairs}) == 3, "3 buses x 3 durations"
    with pytest.raises(ValueError, match="m = 7 tasks are not k fault buses"):
        stratified_sampler(tasks, 5, 7)


# --------------------------------------------------------------------------- #
# Bad input
# --------------------------------------------------------------------------- #

def test_raw_files_of_another_grid_name_both_files_and_the_difference(shared_cases, tmp_path):
    text = (shared_cases / BASE).read_text()
    changed = tmp_path / "changed.raw"
    changed.write_text(text.replace("     2,      3,'1 ',", "     2,      3,'2 ',", 1))
    with pytest.raises(ValueError, match=r"changed.raw and .*smallX_v30.raw are not one grid: "
                                         r"branches \(from, to, circuit\): entry \d+ is "
                                         r"\(2, 3, '1'\) against \(2, 3, '2'\)"):
        from_files([shared_cases / BASE, changed], shared_cases / DYR, shared_cases / TASK)


@pytest.mark.parametrize("key, value, message", [
    ("actionScopeAry", ["Bus504", "Bus507", "Bus999"],
     r"actionScopeAry: 'Bus999': the case .* has no bus 999"),
    ("faultBusCandidates", ["Bus4", "Node7"], r"faultBusCandidates: 'Node7' is not a bus"),
    ("observationScopeAry", ["Bus4", "Bus9990"], r"observationScopeAry: 'Bus9990'"),
    ("unstableReward", "-1000", r"unstableReward = '-1000': must be a number"),
])
def test_task_json_naming_a_missing_bus_or_a_bad_value(shared_cases, tmp_path, key, value,
                                                       message):
    data = json.loads((shared_cases / TASK).read_text())
    path = tmp_path / "task.json"
    path.write_text(json.dumps({**data, key: value}))
    with pytest.raises(ValueError, match=f"task.json: {message}"):
        from_files(shared_cases / BASE, shared_cases / DYR, path)


@pytest.mark.parametrize("toml, message", [
    ('[grid]\nbuiltin = "ieee39_fidvr"\n[env]\nhistory = "ten"\n',
     r"study.toml: env.history = 'ten': must be int"),
    ('[grid]\nbuiltin = "ieee39_fidvr"\n[params]\nc_volt = 1.0\n',
     r"study.toml: \[params\] unknown keys \['c_volt'\]"),
    ('[grid]\nraw = ["nowhere.raw"]\n', r"study.toml: grid.raw = 'nowhere.raw': no such file"),
    ('[grid]\nbuiltin = "ieee39_fidvr"\n[tasks.test]\nfault_buses = [4, 999]\n',
     r"tasks.test.fault_buses: buses \[999\] are not in the case"),
    ('[grid]\nbuiltin = "ieee39_fidvr"\n[tasks.extra]\nfault_buses = [4]\n',
     r"tasks.extra needs \['fault_durations'\]"),
    ('grid = 3\n', r"study.toml: grid = 3: must be a table"),
    ('[grid]\nbuiltin = "ieee39_fidvr"\nload_levels = [2.0]\n', r"load_level = 2.0"),
])
def test_bad_study_files_name_the_key_and_value(tmp_path, toml, message):
    path = tmp_path / "study.toml"
    path.write_text(toml)
    with pytest.raises(ValueError, match=message):
        read_study(path)


def test_a_study_file_on_a_base_overrides_key_by_key(tmp_path):
    """`base` names another study file (relative to this one): its tables merge key by key
    (the base's train set keeps its buses, takes the new durations), other values replace."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "base.toml").write_text(
        'name = "base"\n[grid]\nbuiltin = "ieee39_fidvr"\n[env]\nepisode = 6.0\n'
        '[tasks.train]\nfault_buses = [4, 15]\nfault_durations = [0.05]\n')
    derived = tmp_path / "sub" / "derived.toml"
    derived.write_text('base = "../base.toml"\nname = "derived"\n[env]\n'
                       'action_mask = "hadrec"\n[tasks.train]\nfault_durations = [0.0, 0.08]\n'
                       '[params]\nc_normal = 3.0\n')
    study = read_study(derived)
    assert study.name == "derived" and study.config.episode == 6.0
    assert study.config.action_mask == "hadrec" and study.params.c_normal == 3.0
    assert study.task_set("train").fault_buses == (4, 15)
    assert study.task_set("train").fault_durations == (0.0, 0.08)
    assert len(study.tasks("train+test")) == 4 + len(study.tasks("test"))
    (tmp_path / "base.toml").write_text('base = "sub/derived.toml"\n')
    with pytest.raises(ValueError, match=r"cannot be its own base \(chain: .*derived.toml -> "
                                         r".*base.toml -> .*derived.toml\)"):
        read_study(derived)
    derived.write_text('base = "nowhere.toml"\n')
    with pytest.raises(ValueError, match=r"derived.toml: base = 'nowhere.toml': no such file"):
        read_study(derived)


def test_policy_of_another_layout_is_refused_by_name(tmp_path, ieee39):
    """A saved policy knows its layout; evaluating it on a study with other buses names both."""
    from experiments.common.evaluation import evaluate

    folder = tmp_path / "policy"
    folder.mkdir()
    layout = {"observed_buses": [4, 504], "action_buses": [504], "history": 1,
              "include_action_status": True}
    (folder / "policy.json").write_text(json.dumps({
        "spec": {"kind": "linear", "obs_size": 3, "action_size": 1, "hidden": [],
                 "action_low": -0.2, "action_high": 0.0}, "study": "tiny", "layout": layout}))
    np.savez(folder / "policy.npz", theta=np.zeros(4), mean=np.zeros(3), std=np.ones(3))
    with pytest.raises(ValueError, match=r"trained on study 'tiny'\) has the layout "
                                         r"\{'observed_buses': \[4, 504\].*; study "
                                         r"'ieee39_fidvr' has \{'observed_buses': \[4, 504, 7"):
        evaluate(ieee39, f"policy:{folder}", "test")


def test_policy_trained_under_another_action_mask_masks_its_own_requests(tmp_path, ieee39,
                                                                         monkeypatch):
    """A saved policy records the action mask it was trained under; loaded on a study without
    it, it masks its own requests and says so (own_mask=False: unmasked, and the warning says
    its requests pass otherwise than in training); the latency benchmark times it."""
    from baselines import controllers
    from baselines.controllers import load

    folder = tmp_path / "policy"
    folder.mkdir()
    n_obs = ieee39.env().obs_size
    (folder / "policy.json").write_text(json.dumps({
        "spec": {"kind": "linear", "obs_size": n_obs, "action_size": 3, "hidden": [],
                 "action_low": -0.2, "action_high": 0.0}, "study": "masked",
        "action_mask": "hadrec"}))
    np.savez(folder / "policy.npz", theta=np.zeros(3 * n_obs + 3), mean=np.zeros(n_obs),
             std=np.ones(n_obs))
    with pytest.warns(UserWarning, match=r"trained with action_mask = 'hadrec' \(study "
                                         r"'masked'\); study 'ieee39_fidvr' has 'none': it "
                                         r"masks its own requests as in training"):
        own = load(f"policy:{folder}", ieee39)
    with pytest.warns(UserWarning, match=r"its requests pass otherwise than in training"):
        plain = load(f"policy:{folder}", ieee39, own_mask=False)
    assert (own.own_mask, plain.own_mask) == ("hadrec", None)
    assert own.apply is not plain.apply

    class UnderItsMask:  # the study it was trained on: all `load` reads of a study
        name = "masked"

        def env(self, **changes):
            return ieee39.env(action_mask="hadrec", **changes)

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the same mask: nothing to warn of
        assert load(f"policy:{folder}", UnderItsMask()).own_mask is None
        info = json.loads((folder / "policy.json").read_text())
        (folder / "policy.json").write_text(json.dumps({**info, "self_mask": True}))
        assert load(f"policy:{folder}", UnderItsMask()).own_mask == "hadrec", (
            "trained with --self-mask: it masks its own requests under its mask too")
        (folder / "policy.json").write_text(json.dumps({**info, "self_mask": True,
                                                        "arming_level": 0.85}))
        monkeypatch.setattr(controllers, "masked",
                            lambda apply, mask, env, level, late: (mask, level, late))
        armed = load(f"policy:{folder}", UnderItsMask())
        assert (armed.apply, armed.arming_level) == (("hadrec", 0.85, None), 0.85), (
            "and with the arming level it was trained with")
        assert load(f"policy:{folder}", UnderItsMask(), arming_level=0.8).apply == (
            "hadrec", 0.8, None), "or the one it is given where it runs"
        (folder / "policy.json").write_text(json.dumps({**info, "self_mask": True,
                                                        "arming_level": 0.85,
                                                        "arming_late": 3.0}))
        late = load(f"policy:{folder}", UnderItsMask())
        assert (late.apply, late.arming_late) == (("hadrec", 0.85, 3.0), 3.0), (
            "armed late as its policy.json says")
        assert load(f"policy:{folder}", UnderItsMask(), arming_late=2.0).apply == (
            "hadrec", 0.85, 2.0), "or as it is given where it runs"
        monkeypatch.undo()
        with pytest.raises(ValueError, match=r"--arming-level = 0: allowed 0 < p.u. < 2"):
            load(f"policy:{folder}", UnderItsMask(), arming_level=0)
        (folder / "policy.json").write_text(json.dumps(info))
        monkeypatch.setattr(controllers, "masked",
                            lambda apply, mask, env, level, late: (mask, level))
        assert load(f"policy:{folder}", UnderItsMask(), arming_level=0.8).apply == (
            "hadrec", 0.8), "trained under the mask the study applies: armed all the same"
        monkeypatch.undo()
        (folder / "policy.json").write_text(json.dumps({**info, "action_mask": "none"}))
        with pytest.raises(ValueError, match=r"--arming-level: policy:\S+ was trained without "
                                             r"an action mask, so it has no mask to arm"):
            load(f"policy:{folder}", UnderItsMask(), arming_level=0.8)
        with pytest.raises(ValueError, match=r"--arming-late: policy:\S+ was trained without "
                                             r"an action mask, so it has no mask to arm"):
            load(f"policy:{folder}", UnderItsMask(), arming_late=3.0)
        (folder / "policy.json").write_text(json.dumps(info))
    # the latency benchmark (the reproduction's tab3) times it deciding from a faulted state
    from experiments.bench.controller_latency import bench_study

    with pytest.warns(UserWarning, match=r"masks its own requests"):
        rows = bench_study("ieee39_fidvr", batch=2, calls=1, mpc=None, mpc_batch=2,
                           policies={"masked": str(folder)})["controllers"]
    assert [r["controller"] for r in rows] == ["masked", "uvls"]


def test_every_field_of_a_definition_is_written(pnnl39, tmp_path):
    import tomllib

    path = tmp_path / "study.toml"
    write_study(pnnl39, path)
    data = tomllib.loads(path.read_text())
    assert set(data["env"]) == set(pnnl39.config.values()) - {
        "recovery_buses", "coarse_dt", "coarse_sweeps", "motor_step", "obs_interval",
        "sweeps"}, "None fields are left out, every other one is explicit"
    assert data["compile"]["sweeps"] == pnnl39.config.solver.sweeps, \
        "the solver's sweeps, where study files have always written them"
    assert set(data["params"]) == {f.name for f in dataclasses.fields(EnvParams)}
    assert all(p.startswith("/") for p in data["grid"]["raw"]), "absolute paths"
    assert "builtin" not in data["grid"] and len(data["grid"]["raw"]) == 3
    assert "base_load_levels" not in data["grid"], \
        "none: left out, so a study's written text (and its run folders' names) is as before"


def test_the_papers_300_bus_system_from_its_files(shared_cases):
    """The InterPSS-era 300-bus files with their composite loads: the task JSON's
    "Bus<N>_loadBus" action buses resolve to the composite loads' load buses, and the zone-1
    scope gives the paper's 154 observed buses and 200 inputs."""
    folder = shared_cases / "ieee300"
    task = folder / ("IEEE300_RL_loadShedding_zone1_continuous_LSTM_new_lessfaultbuses_"
                     "moreActionBuses_multipfcases.json")
    study = from_files(folder / "IEEE300Bus_modified_noHVDC_v2.raw",
                       folder / "IEEE300_dyn_cmld_zone1.dyr", task)
    config, model = study.config, study.point(0)
    assert (len(config.observed_buses), len(config.action_buses), study.env().obs_size) == (
        154, 46, 200)
    names = json.loads(task.read_text())["actionScopeAry"]
    assert [model.bus_names[model.bus_index(b)] for b in config.action_buses] == names
    assert not [n for n in study.notes if "but the case gives" in n]


# --------------------------------------------------------------------------- #
# Operating points made from the base case (grid.base_load_levels)
# --------------------------------------------------------------------------- #

ALLLOAD_39 = {0.8: "ieee39/baseCases/IEEE39bus_multiloads_xfmr4_smallX_v30_allload_per80.raw",
              1.1: "ieee39/baseCases/IEEE39bus_multiloads_xfmr4_smallX_v30__allload_per110.raw"}


def test_base_load_levels_make_the_pnnl_allload_points(shared_cases, tmp_path):
    """grid.base_load_levels against the PNNL 39-bus `allload` files made from the same base
    case: at 80 % (every load's P and Q x 0.8 there too) the power flow is theirs to 1e-9
    p.u.; at 110 % the loads' P and the units' dispatch are theirs (their file scales the Q
    of some loads by 0.67-0.89, so voltages are not compared). Written and read back with
    --raw, the levels stay with the file's base case."""
    path = tmp_path / "study.toml"
    path.write_text(f'[grid]\nraw = ["{shared_cases / BASE}"]\nbase_load_levels = [0.8, 1.1]\n'
                    f'dyr = "{shared_cases / DYR}"\ntask_config = "{shared_cases / TASK}"\n')
    study = read_study(path)
    stem = (shared_cases / BASE).stem
    assert [p.label for p in study.points] == [stem, f"{stem}_load80", f"{stem}_load110"]
    for point, (level, file) in zip(study.points[1:], ALLLOAD_39.items()):
        theirs = read_raw(shared_cases / file)
        np.testing.assert_allclose(point.case.loads.p_power, theirs.loads.p_power, rtol=1e-12)
        slack = point.case.buses.kind[point.case.generators.bus] == SLACK
        np.testing.assert_allclose(point.case.generators.pg[~slack],
                                   theirs.generators.pg[~slack], rtol=1e-12)
    ours, theirs = study.points[1].power_flow, solve(read_raw(shared_cases / ALLLOAD_39[0.8]))
    np.testing.assert_allclose(ours.vm, theirs.vm, atol=1e-9)
    np.testing.assert_allclose(ours.va, theirs.va, atol=1e-9)
    write_study(study, tmp_path / "written.toml")
    assert read_study(tmp_path / "written.toml").definition == study.definition
    elsewhere = read_study(tmp_path / "written.toml", raw=[shared_cases / POINTS[1]])
    assert [p.label for p in elsewhere.points] == [(shared_cases / POINTS[1]).stem]


def test_reactive_room_lets_the_300_bus_base_carry_20_percent_more_load(shared_cases):
    """The 300-bus base case with every load and dispatch at 120 %: its power flow does not
    converge within the units' reactive limits; widened to what the level needs (as the
    PNNL `baseCases` files raise QMAX, 36 units in their +20 % file), it converges, each unit
    inside its limits, and zone 1's voltages sag as in their file (mean -0.0069 p.u. here,
    -0.0057 there; within 0.002 p.u.: their file also switches 31 shunts)."""
    folder = shared_cases / "ieee300"
    base = read_raw(folder / "IEEE300Bus_modified_noHVDC_v2.raw")
    heavier = at_load_level(base, 1.2, "load120", "test")
    with pytest.raises(PowerFlowError, match="did not converge"):
        solve(heavier)
    roomy = with_reactive_room(heavier)
    flow = solve(roomy)
    gen = roomy.generators
    assert np.all((flow.qg <= gen.qmax + 1e-9) & (flow.qg >= gen.qmin - 1e-9))
    assert 30 <= int(np.sum(gen.qmax != base.generators.qmax)) <= 45
    zone1 = base.buses.zone == 1
    sag = (flow.vm - solve(base).vm)[zone1].mean()
    theirs = read_raw(folder / "baseCases/IEEE300Bus_modified_noHVDC_v2_scalepercent_20.raw")
    their_sag = (solve(theirs).vm - solve(base).vm)[zone1].mean()
    assert sag == pytest.approx(their_sag, abs=0.002)


# --------------------------------------------------------------------------- #
# Issue 28: every value range-checked, named as the user wrote it
# --------------------------------------------------------------------------- #

ONE_SET = '[tasks.test]\nfault_buses = [4]\n'


@pytest.mark.parametrize("toml, message", [
    ('[params]\nc_voltage = nan\n', r"study.toml: params.c_voltage = nan: must be finite"),
    ('[params]\nunstable_penalty = inf\n', r"params.unstable_penalty = inf: must be finite"),
    ('[params]\nc_shed = -150.0\n', r"params.c_shed = -150.0: must lie in \[0, 1e\+09\]"),
    ('[params]\nrecovery_level = -0.5\n', r"params.recovery_level = -0.5: must lie in "
                                          r"\(0, 2\) p.u."),
    ('[params]\naction_low = -0.1\naction_high = -0.2\n',
     r"params.action_low = -0.1: must be <= action_high = -0.2"),
    ('[params]\naction_high = nan\n', r"params.action_high = nan: must be finite"),
    ('[env]\ndt = 0.0\n', r"study.toml: env.dt = 0.0: must lie in \[0.0001, 0.05\] s"),
    ('[env]\ndt = 1e-12\n', r"env.dt = 1e-12: must lie in \[0.0001, 0.05\] s"),
    ('[env]\nagent_dt = inf\n', r"env.agent_dt = inf: must be finite, in \(0, 60\] s"),
    ('[env]\nagent_dt = nan\n', r"env.agent_dt = nan: must be finite"),
    ('[env]\nagent_dt = 0.1003\n', r"env.agent_dt = 0.1003: must be a whole number"),
    ('[env]\ncoarse_dt = 0.03\n', r"env.agent_dt = 0.1: must be a whole number \(>= 1\) of "
                                 r"simulation steps coarse_dt = 0.03 s"),
    ('[env]\ncoarse_dt = 0.01\ncoarse_sweeps = 0\n', r"env.coarse_sweeps = 0: must lie in "
                                                    r"\[1, 100\] network sweeps"),
    ('[env]\nmotor_step = "implicit"\n',
     r"env.motor_step = 'implicit': must be one of \('exponential', 'rosenbrock'\)"),
    ('[env]\nepisode = inf\n', r"env.episode = inf: must be finite"),
    ('[env]\nhistory = 100000000000000000\n', r"env.history = 100000000000000000: must lie in "
                                             r"\[1, 1000\] observations"),
    ('[env]\nobserved_buses = [4, 7, 4]\n', r"env.observed_buses = \[4, 7, 4\]: 4 is listed "
                                            "more than once"),
    ('[env]\naction_buses = [4]\n', r"study.toml: env.action_buses = \[4\]: bus 4 carries no "
                                    "load"),
    ('[env.bounds]\nmax_voltage = -1.0\n', r"max_voltage = -1.0: must lie in \(0, 1e\+06\]"),
    (ONE_SET + 'fault_durations = [nan]\n',
     r"study.toml: tasks.test.fault_durations\[0\] = nan: must be finite"),
    (ONE_SET + 'fault_durations = [0.1]\nfault_r = -0.01\n',
     r"tasks.test.fault_r = -0.01: must lie in \[0, 1e\+06\] p.u."),
    (ONE_SET + 'fault_durations = [0.1]\nfault_x = nan\n', r"tasks.test.fault_x = nan"),
    (ONE_SET + 'fault_durations = [0.1]\nfault_starts = [1.0, 20.0]\n',
     r"tasks.test.fault_starts\[1\] = 20.0: the fault must start inside the episode "
     r"\(episode = 10 s\)"),
])
def test_out_of_range_study_values_are_named(tmp_path, toml, message):
    """NaN, inf, wrong signs and inconsistent values in a study file: an error naming the key
    as written, with the allowed range and unit."""
    path = tmp_path / "study.toml"
    path.write_text('[grid]\nbuiltin = "ieee39_fidvr"\n' + toml)
    with pytest.raises(ValueError, match=message):
        read_study(path)


@pytest.mark.parametrize("grid, message", [
    ('builtin = "ieee39"', r"study.toml: grid.builtin = 'ieee39': a network without dynamic "
                           "data; study cases: .*ieee39_fidvr"),
    ('builtin = "ieee39_fidvr"\nload_levels = []', r"study.toml: grid.load_levels is empty"),
    ('builtin = "ieee39_fidvr"\nload_levels = [-1.0]',
     r"study.toml: grid.load_levels\[0\] = -1.0: must lie in \(0, 10\]"),
    ('builtin = "ieee39_fidvr"\nbase_load_levels = [1.1]',
     r"study.toml: grid.builtin = 'ieee39_fidvr': a built-in study reads no files: leave out "
     r"base_load_levels"),
])
def test_bad_builtin_grid_is_named(tmp_path, grid, message):
    """A network name or an empty load-level list: no TypeError or IndexError."""
    path = tmp_path / "study.toml"
    path.write_text(f"[grid]\n{grid}\n")
    with pytest.raises(ValueError, match=message):
        read_study(path)


@pytest.mark.parametrize("key, value, message", [
    ("unstableReward", 1000, r"unstableReward = 1000: must lie in \[-1e\+12, -0\]"),
    ("observationWeight", float("nan"), r"observationWeight = nan: must be a number"),
    ("minVoltRecoveryLevel", -0.5, r"minVoltRecoveryLevel = -0.5: must lie in \(0, 2\) p.u."),
    ("actionPenalty", -1.0, r"actionPenalty = -1.0: must lie in \[0, 1e\+09\]"),
    ("actionValueRanges", [[0.0, -0.2]], r"actionValueRanges\[0\]\[0\] = 0.0: must be <= "
                                          "action_high = -0.2"),
    ("faultDurationCandidates", [0.1, -0.05], r"faultDurationCandidates\[1\] = -0.05: must lie "
                                               r"in \[0, 3600\] s"),
    ("historyObservationSize", 10 ** 20, r"historyObservationSize = 100000000000000000000: "
                                         r"must lie in \[1, 1000\]"),
    ("envStepTimeInSec", 0, r"envStepTimeInSec = 0: must lie in \(0, 60\] s"),
    ("actionScopeAry", ["Bus504", "Bus507", "Bus504"], r"actionScopeAry = .*: Bus504 is listed "
                                                        "more than once"),
    # every list: no entry repeated (names compared without case), none empty
    ("faultBusCandidates", ["Bus4", "bus4"], r"faultBusCandidates = \['Bus4', 'bus4'\]: bus4 is "
                                             "listed more than once"),
    ("faultStartTimeCandidates", [0.05, 0.05], r"faultStartTimeCandidates = \[0.05, 0.05\]: "
                                               "0.05 is listed"),
    ("faultDurationCandidates", [0.0, 0.05, 0.0], r"faultDurationCandidates = .*: 0.0 is listed"),
    ("observationScopeAry", ["Bus4", "BUS4"], r"observationScopeAry = .*: BUS4 is listed"),
    ("faultBusCandidates", [], r"faultBusCandidates = \[\]: must be a non-empty list"),
    ("faultDurationCandidates", [], r"faultDurationCandidates = \[\]: must be a non-empty list"),
    ("actionValueRanges", [], r"actionValueRanges = \[\]: must be a list of \[low, high\]"),
])
def test_task_json_values_are_range_checked(shared_cases, tmp_path, key, value, message):
    """Out-of-range PNNL task values, and lists that repeat an entry or are empty, are named
    by file and key at reading."""
    from jaxgrid.study.pnnl import read_task_config

    data = json.loads((shared_cases / TASK).read_text())
    path = tmp_path / "task.json"
    path.write_text(json.dumps({**data, key: value}))
    with pytest.raises(ValueError, match=f"task.json: {message}"):
        read_task_config(path)


@pytest.mark.parametrize("change, message", [
    ({"simuTimeStepSec": 0}, r"simuTimeStepSec = 0: must lie in \[0.0001, 0.05\] s"),
    ({"totalSimuTimeSec": 1e9}, r"totalSimuTimeSec = 1000000000.0: must lie in \(0, 3600\] s"),
    ({"acscConfigBean": {"zLG": {"re": -0.1, "im": 0.0}}}, r"acscConfigBean.zLG.re = -0.1: must "
                                                           r"lie in \[0, 1e\+06\] p.u."),
])
def test_sim_json_values_are_range_checked(shared_cases, tmp_path, change, message):
    from jaxgrid.study.pnnl import read_sim_config

    data = json.loads((shared_cases / SIM).read_text())
    path = tmp_path / "sim.json"
    path.write_text(json.dumps({**data, **change}))
    with pytest.raises(ValueError, match=f"sim.json: {message}"):
        read_sim_config(path)


def test_cross_checks_name_the_pnnl_key(shared_cases, tmp_path):
    """agent_dt not a multiple of the file's dt: named by the task file's key."""
    data = json.loads((shared_cases / TASK).read_text())
    path = tmp_path / "task.json"
    path.write_text(json.dumps({**data, "envStepTimeInSec": 0.1003}))
    with pytest.raises(ValueError, match=r"task.json: envStepTimeInSec = 0.1003: must be a whole "
                                         r"number \(>= 1\) of simulation steps"):
        from_files(shared_cases / BASE, shared_cases / DYR, path, shared_cases / SIM)


def test_pnnl_39_bus_study_file_has_the_papers_settings(shared_cases):
    """studies/ieee39_pnnl.toml (read in place, with ../shared beside the checkout): the
    paper's training set (buses 4, 15, 21 × 0/0.05/0.08 s at 1.0 s, base case: 9 tasks), its
    action range [-0.2, 0], history 10/10/1 by policy kind, and the measured step (2 ms, one
    sweep)."""
    study = read_study(REPO / "studies" / "ieee39_pnnl.toml")
    train = study.tasks("train")
    assert sorted({(s.fault_bus, s.fault_duration, s.fault_start) for s in train}) == [
        (b, d, 1.0) for b in (4, 15, 21) for d in (0.0, 0.05, 0.08)]
    assert {s.operating_point for s in train} == {0} and len(study.tasks("test")) == 120
    assert (study.params.action_low, study.params.action_high) == (-0.2, 0.0)
    assert [study.history(k) for k in ("linear", "fnn", "lstm")] == [10, 10, 1]
    assert (study.config.dt, study.config.solver.sweeps) == (0.002, 1)


def test_pnnl_39_bus_gridpack_study_file_is_the_published_policies_environment(shared_cases):
    """studies/ieee39_pnnl_gp.toml: HADREC's GridPACK environment of the published 39-bus
    networks: the GridPACK task file's buses, faults, reward and 8-s recovery time, 81 agent
    steps (so the recovery check, 8 s after clearing, falls after every episode), samples
    every 0.02 s and requests up to 1 % dropped."""
    study = read_study(REPO / "studies" / "ieee39_pnnl_gp.toml")
    config, params = study.config, study.params
    assert (config.observed_buses, config.action_buses) == ((504, 507, 508, 518),
                                                            (504, 507, 518))
    assert sorted((s.fault_bus, s.fault_duration, s.fault_start)
                  for s in study.tasks("train")) == [
        (b, d, 1.0) for b in (4, 15, 21) for d in (0.0, 0.05, 0.08)]
    assert (params.c_voltage, params.c_shed, params.c_invalid, params.c_prefault,
            params.unstable_penalty, params.recovery_level, params.recovery_time,
            params.action_low, params.action_high) == (260, 150, 3, 100, 1000, 0.95, 8.0,
                                                       -0.2, 0.0)
    assert config.n_steps == 81 and 1.0 + params.recovery_time > config.episode
    assert (config.samples_per_step, config.action_deadband) == (5, 0.01)
    assert [study.history(k) for k in ("linear", "fnn", "lstm")] == [10, 10, 1]
    assert len(study.tasks("test")) == 120


# --------------------------------------------------------------------------- #
# A study's settings at other operating points (--study FILE --raw R ...)
# --------------------------------------------------------------------------- #

def test_a_study_at_another_raw_file_keeps_its_settings(pnnl39, shared_cases, tmp_path):
    """read_study(FILE, raw=...): the same buses, reward and steps at one RAW file of the
    grid, each task set at that point; its compiled point is, leaf for leaf, the one the
    study built from it."""
    write_study(pnnl39, tmp_path / "study.toml")
    other = read_study(tmp_path / "study.toml", raw=[shared_cases / POINTS[2]])
    assert [p.label for p in other.points] == [pnnl39.points[2].label]
    assert (other.config, other.params) == (pnnl39.config, pnnl39.params)
    assert 3 * len(other.tasks("train")) == len(pnnl39.tasks("train"))
    for ours, theirs in zip(jax.tree.leaves(other.point(0)), jax.tree.leaves(pnnl39.point(2))):
        np.testing.assert_array_equal(ours, theirs)


def test_committed_policy_runs_on_the_study_file_at_another_load_level(shared_cases):
    """`experiments.evaluate --study studies/ieee39_pnnl_mask.toml --raw PERC90.raw
    --controller policy:results/pnnl39/policy` (the study the committed policy is evaluated
    on, README): the paper's settings (action range, LSTM history 1) and HADREC's mask, from
    its base file, at a load level; the generalisation set, which indexed the 12 load levels,
    and the test set both run at the one point, and the committed policy's layout is this
    study's."""
    from baselines.controllers import load

    study = read_study(REPO / "studies" / "ieee39_pnnl_mask.toml",
                       raw=[shared_cases / POINTS[1]])
    assert (study.params.action_low, study.history("lstm")) == (-0.2, 1)
    assert study.config.action_mask == "hadrec"
    assert len(study.tasks("test")) == 120 and len(study.tasks("generalisation")) == 120
    controller = load(f"policy:{REPO / 'results/pnnl39/policy'}", study)
    assert controller.info["action_mask"] == study.config.action_mask, "trained under it"
    env = controller.env
    action, _ = controller.apply(controller.params, np.ones(env.config.history * env.obs_size,
                                                            np.float32), controller.carry, None)
    assert env.config.history == 1 and action.shape == (len(env.action_slots),)
    assert np.all((action >= study.params.action_low) & (action <= study.params.action_high))


@pytest.mark.parametrize("flags, message", [
    (["--raw", "a.raw", "--dyr", "a.dyr"], r"--study with --raw .* drop --dyr"),
    (["--study", "ieee39_fidvr", "--load-levels", "0.9", "--raw", "a.raw"],
     r"--study with --raw .* --load-levels"),
    (["--study", "ieee39_fidvr", "--raw", "a.raw"], r"built-in 'ieee39_fidvr'.*--load-levels"),
])
def test_study_with_raw_files_names_the_flags_it_cannot_take(flags, message):
    import argparse

    from experiments.common.studyargs import add_study_arguments, study_from_args

    parser = argparse.ArgumentParser()
    add_study_arguments(parser, None)
    args = parser.parse_args(["--study", "x.toml", *flags] if flags[0] == "--raw" else flags)
    with pytest.raises(ValueError, match=message):
        study_from_args(args)
