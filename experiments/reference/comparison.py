"""jaxgrid beside GridPACK: jaxgrid's runs of the same files and faults, sampled as GridPACK's
(`run_jaxgrid`), their comparison (`compare`: per bus RMS and largest |ΔV| after clearing and
the time below 0.9 and 0.8 p.u., per A/C motor its P/Q RMS and stall, restart and thermal-trip
times), `against` for a whole setup, and `plot`.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from experiments.reference.errors import at_times, deviation
from experiments.reference.gridpack_files import FAULT_X, Fault, Run, Setup, edited_dyr
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.grid import GridModel
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.models.acmotor import motor_power
from jaxgrid.models.options import MotorOptions
from jaxgrid.powerflow import PowerFlowOptions, solve
from jaxgrid.simulate import FaultEvent, make_task, simulate_batch, stack_tasks

LEVELS = (0.9, 0.8)  # p.u.: the comparison's "time below" levels

# --------------------------------------------------------------------------- #
# jaxgrid on the same inputs
# --------------------------------------------------------------------------- #

def jaxgrid_model(raw: str, dyr: str, heating: str, contactor: str = "memory",
                  stiff_below: float = MotorOptions().stiff_below) -> GridModel:
    """The compiled model of the files with the default options but the A/C motors'
    `heating` and `contactor` rules and the induction motors' `stiff_below` (s), from a
    power flow without generator Q limits, as GridPACK's (`gridpack_files.Q_LIMITS`)."""
    options = CompileOptions(motors=MotorOptions(heating=heating, contactor=contactor,
                                                 stiff_below=stiff_below))
    case = read_raw(raw)
    pf = solve(case, PowerFlowOptions(enforce_q_limits=False))
    return compile_model(case, read_dyr(dyr), options, pf)


def run_jaxgrid(model: GridModel, faults: list[Fault], t_end: float, dt: float,
                buses, decimation: int = 1) -> list[Run]:
    """jaxgrid's trajectories of `faults` (one vmapped batch), sampled every `decimation`
    steps of dt s."""
    tasks = stack_tasks([make_task(model, FaultEvent(f.bus, f.start, f.duration, 0.0, FAULT_X))
                         for f in faults])
    traj = simulate_batch(model, tasks, t_end, dt, decimation)
    columns = [model.bus_numbers.index(b) for b in buses]
    groups = [(g, k) for g in model.loads if g.model.name == "ACMTBLU1"
              for k in range(len(g.index))]
    motor_bus = np.array([model.bus_numbers[model.load_bus[g.index[k]]] for g, k in groups])
    runs = []
    vm_all = np.asarray(traj.vm)
    for i in range(len(faults)):
        flags = []
        for g, k in groups:
            z = {name: np.asarray(a)[i][:, k]
                 for name, a in traj.load_flags[model.loads.index(g)].items()}
            p = {name: np.asarray(a)[k] if np.ndim(a) else np.asarray(a)
                 for name, a in g.params.items()}
            s = motor_power(p, z, vm_all[i][:, model.load_bus[g.index[k]]], np)
            flags.append(dict(z, p_motor=s.real, q_motor=s.imag))

        def stack(name):
            return np.stack([f[name] for f in flags], axis=1) if flags else np.zeros(
                (traj.t.shape[-1], 0))

        runs.append(Run(t=np.asarray(traj.t)[i], bus_ids=np.asarray(buses),
                        vm=np.asarray(traj.vm)[i][:, columns], motor_bus=motor_bus,
                        status_a=stack("run_a"), status_b=stack("run_b"),
                        theta_a=stack("theta_a"), theta_b=stack("theta_b"),
                        p_motor=stack("p_motor"), q_motor=stack("q_motor")))
    return runs


# --------------------------------------------------------------------------- #
# Comparison
# --------------------------------------------------------------------------- #

def time_below(t: np.ndarray, v: np.ndarray, level: float, after: float) -> float:
    """Seconds (sample count × step) that v (n_t,) spends below `level` p.u. from `after` s."""
    keep = t >= after - 1e-9
    return float(np.sum(v[keep] < level) * (t[1] - t[0]))


def _events(t, flag, falling: bool) -> list[float]:
    """Times (s) at which a 0/1 flag (n_t,) falls (running -> stalled) or rises."""
    flag = np.nan_to_num(flag, nan=1.0) > 0.5
    change = flag[:-1] & ~flag[1:] if falling else ~flag[:-1] & flag[1:]
    return [round(float(x), 4) for x in t[1:][change]]


def _trip_start(t, theta, status, th1t) -> float | None:
    """First time (s) a stalled part's temperature exceeds Th1t (thermal tripping starts)."""
    hot = (theta > th1t) & (np.nan_to_num(status, nan=1.0) < 0.5)
    return round(float(t[np.argmax(hot)]), 4) if hot.any() else None


def compare(ref: Run, ours: Run, fault: Fault, th1t: dict[int, float]) -> dict:
    """Per bus {rms, max_abs (p.u., after clearing), below_0.9/0.8 (s, ref and ours)}; per
    motor bus the RMS of its P and Q after clearing (p.u. motor base) and the stall,
    restart and thermal-trip times (s) in both; the harnesses' one measure
    (`experiments.reference.errors`): ours at ref's samples."""
    after = ref.t >= fault.end - 1e-9
    buses = {}
    for b in ref.bus_ids:
        if b not in ours.bus_ids:
            continue
        v_ref = ref.voltage(int(b))
        v_ours = at_times(ref.t, ours.t, ours.voltage(int(b)))
        max_abs, rms = deviation(v_ours, v_ref, after)
        row = {"rms": rms, "max_abs": max_abs}
        for level in LEVELS:
            row[f"below_{level}"] = [time_below(ref.t, v_ref, level, fault.end),
                                     time_below(ref.t, v_ours, level, fault.end)]
        buses[int(b)] = row
    motors = {}
    for m, b in enumerate(ref.motor_bus):
        if b not in ours.motor_bus:
            continue
        n = list(ours.motor_bus).index(b)
        sides = [(ref, m), (ours, n)]
        power = {}
        for axis in ("p", "q"):
            ours_s = at_times(ref.t, ours.t, getattr(ours, f"{axis}_motor")[:, n])
            _, power[f"{axis}_rms"] = deviation(ours_s, getattr(ref, f"{axis}_motor")[:, m],
                                                after)
        motors[int(b)] = {
            **power,
            "stall": [_events(r.t, r.status_a[:, k], True)[:1] for r, k in sides],
            "restart": [_events(r.t, r.status_b[:, k], False) for r, k in sides],
            "trip_a": [_trip_start(r.t, r.theta_a[:, k], r.status_a[:, k], th1t[int(b)])
                       for r, k in sides]}
    return {"fault": dataclasses.asdict(fault), "buses": buses, "motors": motors}


def worst(result: dict) -> tuple[float, float]:
    """(largest RMS, largest |time below 0.9 difference|) over the buses of a comparison."""
    rows = result["buses"].values()
    return (max(r["rms"] for r in rows),
            max(abs(r["below_0.9"][1] - r["below_0.9"][0]) for r in rows))


def motor_th1t(model: GridModel) -> dict[int, float]:
    """Th1t (p.u.) of each ACMTBLU1 motor by RAW bus number."""
    return {model.bus_numbers[model.load_bus[slot]]: float(np.asarray(g.params["th1t"])[k])
            for g in model.loads if g.model.name == "ACMTBLU1" for k, slot in enumerate(g.index)}


def against(setup: Setup, cases: list[tuple[Fault, Run]], workdir: Path,
            model: GridModel | None = None, t_end: float | None = None) -> list[dict]:
    """[(`compare` dict, jaxgrid's Run)] of jaxgrid (one batch of the faults, sampled as the
    references) against each reference Run, up to t_end (s; default the setup's); jaxgrid's
    model compiled from the setup's files with the default options, unless given."""
    if model is None:
        dyr = edited_dyr(setup.dyr, setup.edit, workdir / "edited.dyr")
        model = jaxgrid_model(setup.raw, dyr, setup.heating, setup.contactor,
                              setup.stiff_below)
    t_end = setup.t_end if t_end is None else t_end
    cases = [(fault, ref.until(t_end)) for fault, ref in cases]
    buses = sorted({int(b) for _, ref in cases for b in ref.bus_ids} & set(model.bus_numbers))
    step = cases[0][1].t[1] - cases[0][1].t[0]
    ours = run_jaxgrid(model, [fault for fault, _ in cases], t_end, setup.dt, buses,
                       max(1, round(step / setup.dt)))
    th1t = motor_th1t(model)
    return [(compare(ref, run, fault, th1t), run) for (fault, ref), run in zip(cases, ours)]


def plot(path: Path, fault: Fault, ref: Run, ours: Run) -> None:
    """Bus voltages of both simulators for one fault (GridPACK solid, jaxgrid dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for k, bus in enumerate(ref.bus_ids):
        if bus in ours.bus_ids:
            color = f"C{k % 10}"
            ax.plot(ref.t, ref.voltage(int(bus)), color=color, label=f"bus {bus} GridPACK")
            ax.plot(ours.t, ours.voltage(int(bus)), color=color, ls="--",
                    label=f"bus {bus} jaxgrid")
    ax.axhline(0.9, color="grey", lw=0.6)
    ax.set(xlabel="t (s)", ylabel="|V| (p.u.)", ylim=(0.0, 1.15),
           title=f"bolted fault at bus {fault.bus}, {fault.start:g}-{fault.end:g} s")
    ax.legend(ncol=2, fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
