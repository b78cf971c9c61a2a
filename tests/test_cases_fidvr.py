"""Built-in FIDVR study cases: build, power flow, task buses, load level, start at rest, FIDVR.

The FIDVR checks run one batch per case (no fault, a severe fault, a mild fault) for
1 s + duration + 4.2 s and read the voltages 4 s after the fault clears. The recovery level
is the PNNL task's `minVoltRecoveryLevel`: 0.95 p.u. for the 39-bus case, 0.90 p.u. for the
300-bus case (whose zone-1 voltages sit at 0.93-0.95 p.u. before any fault, in the MATPOWER
data as in the PNNL files).
"""
import math
import warnings

import numpy as np
import pytest

from jaxgrid import cases
from jaxgrid.cases import StudyCase
from jaxgrid.cases.fidvr import ACMTBLU1_HEADER, LOAD_LEVEL_RANGE
from jaxgrid.compile import CompileOptions, InitWarning, compile_model
from jaxgrid.models.acmotor import Acmtblu1
from jaxgrid.powerflow import solve
from jaxgrid.simulate import FaultEvent, LoadChange, make_task, simulate_batch, stack_tasks

from experiments.diagnostics.plot_fidvr import draw, motor_shares

NAMES = ("ieee39_fidvr", "ieee300_fidvr")
# name: (observed, action, motor bus counts, recovery level p.u., severe fault, mild fault);
# faults as (bus, duration s), all starting at 1 s.
EXPECT = {
    "ieee39_fidvr": (8, 3, 3, 0.95, (4, 0.08), (4, 0.02)),
    "ieee300_fidvr": (140, 34, 34, 0.90, (3, 0.10), (3, 0.03)),
}
FAULT_START = 1.0
SETTLE = 4.0  # s after clearing at which recovery is judged
DECIMATION = 10
SHED_AT = 1.2  # s: the shedding test's load change, shortly after the severe fault
FLAT_TOL = 1e-4  # p.u. (as tests/test_simulate.py); measured drift < 1e-6 in float32


@pytest.fixture(scope="module", params=NAMES)
def study(request) -> StudyCase:
    return cases.load(request.param)


@pytest.fixture(scope="module")
def model(study):
    """Strict compile (every record supported, ACMTBLU1 included), float32; the action buses
    are the load slots, as `jaxgrid.study.builtin` compiles them."""
    return compile_model(study.case, study.dyr, CompileOptions(load_buses=study.action_buses))


@pytest.fixture(scope="module")
def fidvr_runs(study, model):
    """(t, vm, fault durations, motor shares (3, batch, n_t)) of the batch [no fault, severe
    fault, mild fault, severe fault with 20 % of every motor bus's load shed at SHED_AT]."""
    *_, severe, mild = EXPECT[study.name.rsplit("_load", 1)[0]]
    faults = (None, FaultEvent(severe[0], FAULT_START, severe[1]),
              FaultEvent(mild[0], FAULT_START, mild[1]),
              FaultEvent(severe[0], FAULT_START, severe[1]))
    t_end = FAULT_START + severe[1] + SETTLE + 0.2
    changes = [[LoadChange(b, SHED_AT, 0.2 if k == 3 else 0.0) for b in study.motor_buses]
               for k in range(len(faults))]
    tasks = stack_tasks([make_task(model, f, c) for f, c in zip(faults, changes)])
    traj = simulate_batch(model, tasks, t_end, study.dt, decimation=DECIMATION)
    assert not np.any(np.asarray(traj.diverged)), f"{study.name}: a rollout diverged"
    return (np.asarray(traj.t)[0], np.asarray(traj.vm), (0.0, severe[1], mild[1], severe[1]),
            motor_shares(model, traj))


def _columns(model, buses):
    index = {b: i for i, b in enumerate(model.bus_numbers)}
    return [index[b] for b in buses]


def test_builds_with_records_for_every_unit_and_motor(study):
    base = study.name.rsplit("_load", 1)[0]
    assert study.name == f"{base}_load100" and study.load_level == 1.0
    assert study.dyr.source == f"jaxgrid.cases.{base}"
    assert [r.line for r in study.dyr.records] == list(range(1, len(study.dyr.records) + 1))
    gen = study.case.generators
    for k in np.flatnonzero(gen.in_service):
        key = (int(study.case.buses.number[gen.bus[k]]), gen.gen_id[k])
        models = {r.model for r in study.dyr.records if (r.bus, r.device_id) == key}
        assert {"GENROU", "IEEET1"} <= models, f"{base}: unit {key} has only {models}"
    motors = study.dyr.by_model("ACMTBLU1")
    assert tuple(r.bus for r in motors) == study.motor_buses
    for r in motors:
        assert r.record_type == "USRLOD" and r.header == ACMTBLU1_HEADER
        # the 35 CONs and GridPACK's CON(36), the motor's share of its record: all of it
        assert len(r.cons) == len(Acmtblu1.cons) + 1, f"{r.source}:{r.line}: CON count"
        assert r.cons[-1] == 1.0, f"{r.source}:{r.line}: the motor takes its whole record"


def test_power_flow_converges(study):
    pf = solve(study.case)
    assert pf.converged and pf.max_mismatch < 1e-8, f"{study.name}: {pf.max_mismatch:g}"
    on = study.case.buses.kind != 4
    assert 0.9 < pf.vm[on].min() and pf.vm[on].max() < 1.1, f"{study.name}: voltage range"


def test_task_buses_exist_and_carry_loads(study):
    n_obs, n_act, n_mot, *_ = EXPECT[study.name.rsplit("_load", 1)[0]]
    assert (len(study.observed_buses), len(study.action_buses), len(study.motor_buses)) == (
        n_obs, n_act, n_mot)
    for buses in (study.observed_buses, study.action_buses, study.motor_buses):
        assert len(set(buses)) == len(buses), "duplicate bus"
        study.case.bus_index(buses)  # KeyError names a missing bus
    ld = study.case.loads
    records = {(int(study.case.buses.number[b]), i) for b, i in zip(ld.bus, ld.load_id)}
    for r in study.dyr.by_model("ACMTBLU1"):
        assert (r.bus, r.device_id) in records, f"{r.source}:{r.line}: no load record"
    assert set(study.motor_buses) <= set(study.action_buses) <= {b for b, _ in records}
    assert set(study.motor_buses) <= set(study.observed_buses)


@pytest.mark.parametrize("name", NAMES)
def test_load_level_scales_loads_and_dispatch(name):
    lo, _ = LOAD_LEVEL_RANGE[name]
    level = max(lo, 0.8)
    base, scaled = cases.load(name), cases.load(name, load_level=level)
    assert scaled.name == f"{name}_load{100 * level:g}" and scaled.load_level == level
    for field in ("p_power", "q_power"):
        total = getattr(base.case.loads, field).sum()
        np.testing.assert_allclose(getattr(scaled.case.loads, field).sum(), level * total,
                                   rtol=1e-12, err_msg=field)
    np.testing.assert_allclose(scaled.case.generators.pg, level * base.case.generators.pg,
                               rtol=1e-12)
    np.testing.assert_array_equal(scaled.case.generators.mbase, base.case.generators.mbase)
    assert solve(scaled.case).converged


@pytest.mark.parametrize("value", [0.2, 1.6, math.nan, "1.0", True, None])
def test_bad_load_level_is_named(value):
    lo, hi = LOAD_LEVEL_RANGE["ieee39_fidvr"]
    with pytest.raises(ValueError, match=rf"load_level = .*\[{lo}, {hi}\]"):
        cases.load("ieee39_fidvr", load_level=value)


@pytest.mark.parametrize("name", NAMES)
def test_compiles_at_rest_across_load_levels(name):
    """Lenient and strict compiles warn nothing: every device starts at rest inside its limits."""
    lo, hi = LOAD_LEVEL_RANGE[name]
    for level in (lo, hi):
        study = cases.load(name, load_level=level)
        for strict in (False, True):
            with warnings.catch_warnings():
                warnings.simplefilter("error", InitWarning)
                model = compile_model(study.case, study.dyr, CompileOptions(strict=strict))
            assert model.n_gen == int(study.case.generators.in_service.sum())


def test_compile_defaults_make_action_buses_load_slots(study, model):
    slots = [model.load_slot(b) for b in study.action_buses]  # ValueError names a missing one
    assert len(set(slots)) == len(study.action_buses)
    assert len(model.exciters) and len(model.governors) and len(model.loads)


def test_no_fault_stays_above_recovery_level(study, model, fidvr_runs):
    level = EXPECT[study.name.rsplit("_load", 1)[0]][3]
    vm = fidvr_runs[1]
    observed = vm[0][:, _columns(model, study.observed_buses)]
    assert observed.min() >= level, f"{study.name}: flat run dips to {observed.min():.4f} p.u."
    np.testing.assert_allclose(observed, np.broadcast_to(observed[0], observed.shape),
                               atol=FLAT_TOL, err_msg=f"{study.name}: flat run drifts")


def test_severe_fault_stalls_motors_mild_fault_recovers(study, model, fidvr_runs):
    level = EXPECT[study.name.rsplit("_load", 1)[0]][3]
    t, vm, durations, _ = fidvr_runs
    motors = _columns(model, study.motor_buses)
    observed = _columns(model, study.observed_buses)
    at = {k: int(np.searchsorted(t, FAULT_START + d + SETTLE - 1e-6))
          for k, d in enumerate(durations)}
    severe = vm[1, at[1]][motors]
    assert severe.min() < level, (f"{study.name}: no FIDVR, motor buses at "
                                  f"{severe.min():.3f} p.u. 4 s after clearing")
    mild = vm[2, at[2]][observed]
    assert mild.min() >= level, (f"{study.name}: mild fault does not recover, an observed bus "
                                 f"at {mild.min():.3f} p.u. 4 s after clearing")


def test_shedding_20_percent_after_the_fault_speeds_recovery(study, model, fidvr_runs):
    t, vm, durations, _ = fidvr_runs
    motors = _columns(model, study.motor_buses)
    judged = int(np.searchsorted(t, FAULT_START + durations[1] + SETTLE - 1e-6))
    without, shed = vm[1, judged][motors], vm[3, judged][motors]
    print(f"\n{study.name}: lowest motor-bus voltage 4 s after clearing {without.min():.3f} "
          f"p.u. without, {shed.min():.3f} p.u. with 20 % shed at {SHED_AT} s")
    assert shed.min() > without.min() + 0.01
    assert shed.mean() > without.mean()


def test_severe_fault_stalls_motors_and_the_figure_is_drawn(study, model, fidvr_runs, tmp_path):
    """Motor states by MVA share: all running at rest; 4 s after clearing, the severe fault
    leaves a large stalled share (measured 82 % on the 39-bus case, 43 % on the 300-bus
    case; the PNNL study's FIDVR is stalled A/C compressors), the mild fault none."""
    t, _, durations, shares = fidvr_runs
    running, stalled, _ = shares
    np.testing.assert_allclose(running[0], 1.0, atol=1e-6, err_msg="no fault: a motor stops")
    judged = int(np.searchsorted(t, FAULT_START + durations[1] + SETTLE - 1e-6))
    assert stalled[1, judged] > 0.25, f"{study.name}: severe fault stalls {stalled[1, judged]:.0%}"
    assert running[2, judged] > 0.99, f"{study.name}: mild fault leaves {running[2, judged]:.0%}"
    severe = FaultEvent(EXPECT[study.name.rsplit("_load", 1)[0]][4][0], FAULT_START,
                        durations[1])
    draw(study.name, study.observed_buses, model, t, fidvr_runs[1][1], shares[:, 1], severe,
         str(tmp_path / "fidvr.png"))
    assert (tmp_path / "fidvr.png").stat().st_size > 10_000
