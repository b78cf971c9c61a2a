"""Fault-induced delayed voltage recovery on the PNNL reference files (../shared/cases).

Strict mode throughout: every dynamic model of these files is supported. The checks are
the study's: a motor bus still below the recovery level some seconds after clearing
(FIDVR), none without a fault, and load shedding after the fault speeds recovery.
Run with -s to print the voltages each reading of the motor data gives. The InterPSS-era
variant with WECC composite loads (CMLDBLU2) is tested in test_cmld.py and measured by
experiments/bench/cmld.py.
"""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import RawWarning, read_raw
from jaxgrid.models.acmotor import MotorOptions
from jaxgrid.simulate import FaultEvent, LoadChange, make_task, simulate_batch, stack_tasks

MOTOR_BUSES_39 = (504, 507, 518)
READINGS = {  # spec acmtblu1 §3-4: the PSS/E reading (default) and the original study's
    "psse": MotorOptions(),
    "interpss": MotorOptions(share_mode="interpss_bus_total", vx_rule="reference_running1"),
}


def _read(shared_cases, raw, dyr):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RawWarning)  # transformer tap control not modelled
        return read_raw(shared_cases / raw), read_dyr(shared_cases / dyr)


@pytest.fixture(scope="module")
def ieee39(shared_cases):
    """Per reading: (model, trajectories of [no fault, bus-4 fault, bus-4 fault + shedding])."""
    case, dyr = _read(shared_cases, "ieee39/IEEE39bus_multiloads_xfmr4_smallX_v30.raw",
                      "ieee39/IEEE39bus_3AC.dyr")
    out = {}
    for name, reading in READINGS.items():
        model = compile_model(case, dyr, CompileOptions(load_buses=MOTOR_BUSES_39,
                                                        motors=reading))
        keep = [LoadChange(b, 1.2, 0.0) for b in MOTOR_BUSES_39]
        sheds = [LoadChange(b, 1.2, 0.2) for b in MOTOR_BUSES_39]
        tasks = [make_task(model, None, keep), make_task(model, FaultEvent(4, 1.0, 0.08), keep),
                 make_task(model, FaultEvent(4, 1.0, 0.08), sheds)]
        out[name] = model, simulate_batch(model, stack_tasks(tasks), 5.2, 0.002, decimation=10)
    return out


def _at(traj, model, buses, t):
    """(n_task, len(buses)) voltage magnitudes at the sample nearest t (s)."""
    k = int(np.argmin(np.abs(np.asarray(traj.t) - t)))
    return np.asarray(traj.vm)[:, k, [model.bus_index(b) for b in buses]]


@pytest.mark.parametrize("reading", list(READINGS))
def test_ieee39_fault_at_bus_4_leaves_delayed_recovery(ieee39, reading):
    model, traj = ieee39[reading]
    after = _at(traj, model, MOTOR_BUSES_39, 1.08 + 4.0)
    print(f"\n{reading}: V at 4 s after clearing, buses {MOTOR_BUSES_39}: no fault "
          f"{after[0].round(3)}, fault {after[1].round(3)} (diverged: "
          f"{bool(np.asarray(traj.diverged)[1])}), fault + 20 % shed {after[2].round(3)}")
    no_fault = np.asarray(traj.vm)[0][:, [model.bus_index(b) for b in MOTOR_BUSES_39]]
    assert no_fault.min() >= 0.95, f"{reading}: a motor bus is below 0.95 p.u. without a fault"
    assert after[1].min() < 0.95, f"{reading}: every motor bus recovered within 4 s"


def test_ieee39_flat_run_stays_at_the_power_flow_point(ieee39):
    model, traj = ieee39["psse"]
    drift = np.abs(np.asarray(traj.vm)[0] - np.abs(model.v0)).max()
    assert drift < 1e-4, f"flat run drifts {drift:.2e} p.u. with the motors"


def test_ieee39_shedding_after_the_fault_speeds_recovery(ieee39):
    model, traj = ieee39["psse"]
    after = _at(traj, model, MOTOR_BUSES_39, 1.08 + 4.0)
    left = np.asarray(traj.load_left)[2, -1]
    assert left == pytest.approx(0.8), "20 % of each motor bus's load is shed"
    assert after[2].min() > after[1].min() + 0.01, (
        f"shedding 20 % did not raise the lowest motor-bus voltage ({after[1]} -> {after[2]})")


@pytest.fixture(scope="module")
def ieee300(shared_cases):
    """The GridPACK pair: model, action buses, trajectories of [no fault] + training faults."""
    case, dyr = _read(shared_cases, "ieee300/IEEE300Bus_modified_noHVDC_v23_reduce3bigloads.raw",
                      "ieee300/IEEE300_genrou_exdc1_tgov1_zone1ac.dyr")
    task_file = shared_cases / ("ieee300/IEEE300_RL_loadShedding_zone1_continuous_LSTM_"
                                "multipfcases_training_gp.json")
    config = json.loads(task_file.read_text())
    action_buses = tuple(int(b.lower().removeprefix("bus")) for b in config["actionScopeAry"])
    model = compile_model(case, dyr, CompileOptions(load_buses=action_buses))
    faults = [None] + [FaultEvent(b, 1.0, 0.1) for b in (2, 3, 5, 8, 12, 15, 17, 23)]
    tasks = stack_tasks([make_task(model, f) for f in faults])
    return model, action_buses, config, faults, simulate_batch(model, tasks, 6.2, 0.005,
                                                               decimation=20)


def test_ieee300_training_faults_show_delayed_recovery(ieee300):
    model, action_buses, config, faults, traj = ieee300
    level, delay = config["minVoltRecoveryLevel"], config["maxVoltRecoveryTime"]  # 0.9, 5 s
    after = _at(traj, model, action_buses, 1.1 + delay)
    low = (after < level).sum(axis=1)
    print("\nieee300 action buses below", level, "p.u.", delay, "s after clearing:",
          {(f.bus if f else None): int(n) for f, n in zip(faults, low)})
    assert low[0] == 0, "an action bus is below the recovery level without a fault"
    assert low[1:].max() > 0, "no training fault leaves delayed recovery"
