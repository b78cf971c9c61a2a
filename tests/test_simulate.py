"""Dynamic simulation: flat runs, ANDES trajectories, batching, divergence, gradients, CLI.

References nobody here wrote: ANDES (PyPI) time-domain runs of the PSS/E files it ships
(`kundur.raw` + `kundur_full.dyr`, `ieee14.raw` + `ieee14.dyr`, and ieee14 with ESST1A
exciters, and with AC exciters, ESDC2A and its IEEEST, written here), with the same fault.
ANDES's power flow does not enforce generator Q limits, so ours is solved the same way
for the comparison. ieee14's ST2CUT stabilizers are unsupported here and are removed from
the DYR given to both simulators (and its IEEEST but in ieee14_ac).
"""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from experiments.reference.andes_files import run_andes, trajectory_errors, write_psse_dyr
from experiments.simulate import main
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.powerflow import PowerFlowOptions, solve
from jaxgrid.simulate import (FaultEvent, LoadChange, make_task, simulate, simulate_batch,
                              stack_tasks, trajectory)
from tests.conftest import andes_cases_dir

T_END = 10.0
DT = 0.005
FAULT = dict(start=1.0, duration=0.1)
# ANDES comparison bounds (issue 3): outside 30 ms after each event.
V_MAX_ERR, V_RMS_ERR, SPEED_ERR, ANGLE_ERR_DEG = 0.02, 0.005, 1e-3, 3.0
# A flat run must stay within this of the power flow (issue 3).
FLAT_TOL = 1e-4

# ESST1A on every ieee14 machine in place of its exciters, PSS/E order (UEL VOS TR VIMAX VIMIN
# TC TB TC1 TB1 KA TA VAMAX VAMIN VRMAX VRMIN KC KF TF KLR ILR): bus 1 has the WECC values of
# GridPACK's 300-bus file (VIMAX 0.3 added), the others vary them so that during the bus-4
# fault the input limit (buses 1, 3, 8), VAMAX (2), the Ec-scaled ceiling (all), the
# field-current limiter (2), the second lead-lag (2), the rate feedback (2) and bypassed
# lead-lags (6) act, with every UEL and VOS code. The rate feedback sits where the ceiling
# barely binds: ANDES takes it before the EFD limiter, IEEE 421.5 and GridPACK after it (with
# KF = 0.05 on bus 3, whose ceiling binds, the angle error grows to 3.5 degrees).
ESST1A = """\
1 'ESST1A' 1 1 1 0.02 0.3 -0.3 0.51 2.01 0 0 178.9 0.029 7.0 -6.0 4.48 -1.79 0.11 0 1.0 0 2.8 /
2 'ESST1A' 1 2 2 0.01 999 -999 1.0 10.0 0.1 0.05 200 0.02 5.0 -4.0 8.0 -7.0 0.05 0.02 1.0 4.5 2.3 /
3 'ESST1A' 1 3 1 0.02 0.2 -0.2 1.0 5.0 0 0 100 0.05 6.0 -5.0 5.0 -4.0 0.1 0 0.5 0 3.0 /
6 'ESST1A' 1 1 2 0.015 999 -999 0 0 0 0 150 0.03 999 -999 6.0 -5.0 0.08 0 1.0 2.0 2.5 /
8 'ESST1A' 1 2 1 0.02 0.1 -0.1 1.0 1.0 0 0 200 0.02 999 -999 7.0 -6.0 0.2 0 1.0 0 4.0 /
"""
# The AC exciters, ESDC2A and IEEEST: ieee14's own IEEEST (MODE 3, electrical power; T4 0.75,
# washout 1/4.2, KS -2) stays with bus 3's ESST3A; EXAC1 (ACTIVSg2000 bus 2057's values, TR
# 0.02), EXAC2 (IEEE sample values; KH = KL = 1: ANDES initialises its VA with KL in place of
# KH, the same when they are equal), ESAC1A (ACTIVSg2000 bus 4026's, TR 0.02, KA 100 in
# place of 326; KF = 0 and VRMAX/VRMIN ±99: ANDES's ESAC1A has no rate feedback and no VR
# limits) and ESDC2A (IEEE sample values) replace the exciters of buses 1, 2, 6 and 8.
# PSS/E orders (ESAC1A's reordered for ANDES by `andes_dyr`). With KA 326 the exciter
# voltage VE reaches 0 after clearing, where ANDES, without VE's lower limit, lets it and
# EFD go negative (ESAC1A alone on bus 6: 13.8 degrees and 0.061 p.u. apart; 0.52 degrees
# and 0.012 p.u. with the limit taken out).
AC_EXCITERS = """\
1 'EXAC1' 1 0.02 0 0 400 0.05 5.2477 -5.2477 1.1 0.035 1 0.2469 0.5 1 2.7077 0.0366 3.6102 0.1831 /
2 'EXAC2' 1 0.02 0 0 400 0.02 8 -8 25 105 -95 0.6 1 1 0.03 1 0.28 0.35 1 4.4 2.29 0.117 3.05 0.279 /
6 'ESAC1A' 1 0.02 0 0 100 0.1 15.2173 -15.2173 0.9361 0 1 0.2 1 1 4.181 0.0615 5.5747 0.5533 99 -99 /
8 'ESDC2A' 1 0.02 300 0.01 0 0 4.95 -4.9 1 1.33 0.1 0.675 0 2.29 0.117 3.05 0.279 /
"""
ANDES_CASES = {  # name: (raw, dyr, models removed from the DYR, fault bus, records added)
    "kundur": ("kundur/kundur.raw", "kundur/kundur_full.dyr", (), 8, ""),
    "ieee14": ("ieee14/ieee14.raw", "ieee14/ieee14.dyr", ("IEEEST", "ST2CUT"), 4, ""),
    "ieee14_esst1a": ("ieee14/ieee14.raw", "ieee14/ieee14.dyr",
                      ("IEEEST", "ST2CUT", "ESST3A", "EXST1"), 4, ESST1A),
    "ieee14_ac": ("ieee14/ieee14.raw", "ieee14/ieee14.dyr",
                  ("ST2CUT", "EXST1", "ESST3A@1", "ESST3A@6", "ESST3A@8"), 4, AC_EXCITERS),
}


@pytest.fixture(scope="module")
def andes_files(tmp_path_factory):
    """{name: (raw path, filtered DYR path, fault bus)} for ANDES's bundled cases."""
    folder = tmp_path_factory.mktemp("andes")
    out = {}
    for name, (raw, dyr, drop, bus, added) in ANDES_CASES.items():
        path = write_psse_dyr(str(andes_cases_dir() / dyr), str(folder / f"{name}.dyr"), drop)
        with open(path, "a") as f:
            f.write(added)
        out[name] = (str(andes_cases_dir() / raw), path, bus)
    return out


@pytest.fixture(scope="module")
def models(andes_files):
    """Compiled float32 models of the ANDES cases (power flow without Q limits, as ANDES)."""
    out = {}
    for name, (raw, dyr, _) in andes_files.items():
        case = read_raw(raw)
        out[name] = compile_model(case, read_dyr(dyr),
                                  pf=solve(case, PowerFlowOptions(enforce_q_limits=False)))
    return out


@pytest.mark.parametrize("name", list(ANDES_CASES))
def test_fault_matches_andes(name, andes_files, models):
    raw, dyr, bus = andes_files[name]
    ref = run_andes(raw, dyr, T_END, bus, FAULT["start"], FAULT["duration"], tstep=DT)
    model = models[name]
    off_rest = [n for n in model.notes if "at t = 0" in n or "outside its limits" in n]
    assert not off_rest, f"{name}: devices off rest at t = 0: {off_rest}"
    traj = simulate(model, T_END, DT, fault=FaultEvent(bus, **FAULT))
    assert not bool(traj.diverged), f"{name}: rollout diverged at {float(traj.diverged_at)} s"
    errors = trajectory_errors(model, traj, ref,
                               (FAULT["start"], FAULT["start"] + FAULT["duration"]))
    v_max, v_rms, speed, angle = errors.v_max, errors.v_rms, errors.speed, errors.angle_deg
    print(f"{name}: V max {v_max:.4f} rms {v_rms:.5f} speed {speed:.2e} angle {angle:.2f} deg")
    assert v_max <= V_MAX_ERR, f"{name}: bus voltage error {v_max:.4f} p.u."
    assert v_rms <= V_RMS_ERR, f"{name}: RMS bus voltage error {v_rms:.5f} p.u."
    assert speed <= SPEED_ERR, f"{name}: speed error {speed:.2e} p.u."
    assert angle <= ANGLE_ERR_DEG, f"{name}: relative angle error {angle:.2f} deg"


def _flat(model):
    traj = simulate(model, T_END, DT, decimation=100)
    return np.abs(np.asarray(traj.vm) - np.abs(model.v0)).max(), traj


# ieee14_ac's rest is checked at compile time instead (test_fault_matches_andes: no device
# off rest at t = 0), saving its 17-s flat run
@pytest.mark.parametrize("name", [n for n in ANDES_CASES if n != "ieee14_ac"])
def test_flat_run_stays_flat(name, models):
    deviation, traj = _flat(models[name])
    assert not bool(traj.diverged)
    assert deviation < FLAT_TOL, f"{name}: flat run drifts {deviation:.2e} p.u. from the power flow"


@pytest.fixture(scope="module")
def batch(models):
    """Kundur, 2 s, four tasks in one vmapped call; task 2 is forced to diverge (NaN fault)."""
    model = models["kundur"]
    tasks = [make_task(model, FaultEvent(8, 0.5, 0.1), [LoadChange(7, 1.0, 0.0)]),
             make_task(model, FaultEvent(3, 0.5, 0.05), [LoadChange(8, 1.0, 0.2)]),
             make_task(model, FaultEvent(8, 0.5, 0.1, x=float("nan")), [LoadChange(7, 1.0, 0.0)]),
             make_task(model, None, [LoadChange(7, 0.2, 0.3)])]
    return model, tasks, simulate_batch(model, stack_tasks(tasks), 2.0, DT, decimation=10)


def test_batched_equals_one_at_a_time(batch):
    model, tasks, out = batch
    for k in (0, 1, 3):
        single = simulate_batch(model, tasks[k], 2.0, DT, decimation=10, batched=False)
        # float32: identical operations, possibly in another order inside XLA
        np.testing.assert_allclose(np.asarray(out.vm[k]), np.asarray(single.vm), atol=2e-5)
        np.testing.assert_allclose(np.asarray(out.angle[k]), np.asarray(single.angle), atol=1e-4)


def test_one_task_diverges_the_rest_do_not(batch):
    _, _, out = batch
    assert np.asarray(out.diverged).tolist() == [False, False, True, False]
    # a NaN impedance poisons the fault term (0·NaN) from the first step on; divergence is
    # checked once per output sample (10 steps)
    assert float(out.diverged_at[2]) == pytest.approx(10 * DT, abs=1e-6)
    frozen = jax.tree.leaves(jax.tree.map(lambda a: a[2], out.final))
    assert all(np.all(np.isfinite(np.asarray(a))) for a in frozen), "frozen state must stay finite"


def test_load_change_moves_voltage_and_no_retrace(batch):
    model, tasks, out = batch
    before = trajectory._cache_size()
    simulate_batch(model, stack_tasks([tasks[1], tasks[0], tasks[3], tasks[2]]), 2.0, DT,
                   decimation=10)
    assert trajectory._cache_size() == before, "a new batch of tasks must not recompile"
    t = np.asarray(out.t[3])
    bus = model.bus_index(7)
    vm = np.asarray(out.vm[3])[:, bus]
    assert vm[t > 0.5].mean() > vm[0] + 1e-3, "shedding 30 % of bus 7's load must raise its voltage"


@pytest.fixture(scope="module")
def kundur64(andes_files):
    raw, dyr, _ = andes_files["kundur"]
    case = read_raw(raw)
    return compile_model(case, read_dyr(dyr), CompileOptions(precision="float64"),
                         pf=solve(case, PowerFlowOptions(enforce_q_limits=False)))


def test_float32_time_loop_tracks_float64(models, kundur64):
    """The default float32 loop against the float64 switch, 2 s with a bolted fault."""
    fault = FaultEvent(8, 0.5, 0.1)
    single = simulate(models["kundur"], 2.0, DT, fault=fault, decimation=10)
    double = simulate(kundur64, 2.0, DT, fault=fault, decimation=10)
    dv = np.abs(np.asarray(single.vm) - np.asarray(double.vm)).max()
    dw = np.abs(np.asarray(single.speed_dev) - np.asarray(double.speed_dev)).max()
    print(f"float32 vs float64: |dV| {dv:.2e} p.u., |dw| {dw:.2e} p.u.")
    # measured 3e-7 and 4e-8: float32 round-off (~1e-7 relative) over 400 steps; 30x margin
    assert dv < 1e-5 and dw < 1e-6, (dv, dw)


def test_gradient_matches_finite_differences(kundur64):
    """d(mean |V| at the end)/d(shed fraction), float64, against central differences."""
    model = kundur64
    task = make_task(model, FaultEvent(8, 0.1, 0.05), [LoadChange(7, 0.2, 0.1),
                                                        LoadChange(8, 0.2, 0.1)])

    def objective(fractions):
        with jax.enable_x64(True):
            traj = simulate_batch(model, task.replace(load_fraction=fractions), 0.5, DT,
                                  decimation=10, batched=False)
            return jnp.mean(traj.vm[-1])

    with jax.enable_x64(True):
        x = jnp.asarray(task.load_fraction)
        grad = np.asarray(jax.grad(objective)(x))
        h = 1e-5
        fd = [(objective(x.at[k].add(h)) - objective(x.at[k].add(-h))) / (2 * h)
              for k in range(2)]
    assert np.all(np.isfinite(grad))
    # central differences in float64 are good to ~1e-7 relative here; allow 1e-4
    np.testing.assert_allclose(grad, np.asarray(fd), rtol=1e-4)
    assert np.all(np.abs(grad) > 1e-4), "shedding must change the voltages"


def test_cli_writes_npz(andes_files, tmp_path):
    raw, dyr, bus = andes_files["kundur"]
    out = tmp_path / "run.npz"
    code = main(["--raw", raw, "--dyr", dyr, "--fault-bus", str(bus), "--t-end", "2",
                 "--dt", str(DT), "--decimation", "10", "--out", str(out)])
    assert code == 0
    data = np.load(out)
    n_t, n_bus = 41, 10
    assert data["t"].shape == (n_t,) and data["bus_ids"].tolist() == list(range(1, 11))
    assert data["vm"].shape == (n_t, n_bus) and data["va"].shape == (n_t, n_bus)
    assert data["gen_speed"].shape == (n_t, 4) and data["gen_angle"].shape == (n_t, 4)
    assert data["gen_bus"].tolist() == [1, 2, 3, 4] and not bool(data["diverged"])
    assert abs(data["gen_speed"][0] - 1.0).max() < 1e-6
    assert data["vm"][:, bus - 1].min() < 0.01, "the bolted fault must pull bus 8 to ~0"


def test_cli_bad_input_exits_2(andes_files, tmp_path, capsys):
    raw, dyr, _ = andes_files["kundur"]
    code = main(["--raw", raw, "--dyr", dyr, "--fault-bus", "999", "--out", str(tmp_path / "x.npz")])
    assert code == 2
    assert "bus 999" in capsys.readouterr().err


def test_bad_options_are_named(models):
    with pytest.raises(ValueError, match="precision"):
        CompileOptions(precision="float16")
    with pytest.raises(ValueError, match=r"dt = 0.5: must lie in \[0.0001, 0.05\] s"):
        simulate(models["kundur"], 1.0, 0.5)
    with pytest.raises(ValueError, match="bus 5 has no controllable load slot"):
        make_task(models["kundur"], None, [LoadChange(5, 1.0, 0.1)])


def test_observed_buses_are_rows_of_the_whole_solution(batch):
    """`observe` with `buses` (the environment's observed buses) computes only their rows of
    the bus product; with the fault on, from the first task's final state, they equal the
    same rows of the whole solution to float32 rounding (1e-6 p.u., rad)."""
    from jaxgrid import network
    from jaxgrid.simulate import observe
    from jaxgrid.steppers import Solver, fault_active

    model, tasks, trajectories = batch
    task = tasks[0]
    x = jax.tree.map(lambda a: a[0], trajectories.final)
    fault = network.fault_view(model.network, task.fault_bus, task.fault_z)
    t = jnp.asarray(0.55, jnp.float32)
    assert float(fault_active(task, t, DT)) == 1.0
    buses = np.array([7, 2, 9, 0])
    whole = observe(model, x, t, Solver(DT), task, fault)
    part = observe(model, x, t, Solver(DT), task, fault, buses)
    np.testing.assert_allclose(part[0], whole[0][buses], atol=1e-6)
    np.testing.assert_allclose(part[1], whole[1][buses], atol=1e-6)
