"""jaxgrid beside GridPACK: jaxgrid's runs of the same files and faults, sampled as GridPACK's
(`run_jaxgrid`), their comparison (`compare`: per bus RMS and largest |ΔV| after clearing and
the time below 0.9 and 0.8 p.u., per A/C motor, a composite load's motor D included, its P/Q
RMS and stall, restart and thermal-trip times), `against` for a whole setup, `against_saved`
for saved references (the tests), and `plot`.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from experiments.reference.errors import at_times, deviation
from experiments.reference.gridpack_dyr import edited_dyr
from experiments.reference.gridpack_files import FAULT_X, Fault, Run, Setup, load_reference
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.grid import GridModel
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.models.acmotor import motor_power
from jaxgrid.models.options import CompositeOptions, MotorOptions
from jaxgrid.powerflow import PowerFlowOptions, solve
from jaxgrid.simulate import FaultEvent, make_task, simulate_batch, stack_tasks

LEVELS = (0.9, 0.8)  # p.u.: the comparison's "time below" levels
COMPOSITE = ("CMLDBLU2", "CMLDBLU1")  # load-model names whose unit has a motor D

# --------------------------------------------------------------------------- #
# jaxgrid on the same inputs
# --------------------------------------------------------------------------- #

def jaxgrid_model(setup: Setup, dyr: str) -> GridModel:
    """The compiled model of `setup`'s RAW and `dyr` with the default options but the A/C
    motors' heating and contactor rules, the induction motors' stiff_below (s) and the
    composite loads' options of `setup`, from a power flow without generator Q limits, as
    GridPACK's (`gridpack_files.Q_LIMITS`)."""
    options = CompileOptions(
        motors=MotorOptions(heating=setup.heating, contactor=setup.contactor,
                            stiff_below=setup.stiff_below),
        composite=CompositeOptions(**dict(setup.composite)))
    case = read_raw(setup.raw)
    pf = solve(case, PowerFlowOptions(enforce_q_limits=False))
    return compile_model(case, read_dyr(dyr), options, pf)


def _motor_d(group, k: int, prefix: str):
    """(params, flag keys) of unit k's A/C motor in a load group: an ACMTBLU1 (prefix "")
    or a composite load's motor D (prefix "d_")."""
    params = {name[len(prefix):]: np.asarray(a)[k] if np.ndim(a) else np.asarray(a)
              for name, a in group.params.items() if name.startswith(prefix)}
    return params, [name for name in group.model.flags if name.startswith(prefix)]


def run_jaxgrid(model: GridModel, faults: list[Fault], t_end: float, dt: float,
                buses, decimation: int = 1) -> list[Run]:
    """jaxgrid's trajectories of `faults` (one vmapped batch), sampled every `decimation`
    steps of dt s."""
    tasks = stack_tasks([make_task(model, FaultEvent(f.bus, f.start, f.duration, 0.0, FAULT_X))
                         for f in faults])
    traj = simulate_batch(model, tasks, t_end, dt, decimation)
    columns = [model.bus_numbers.index(b) for b in buses]
    groups = [(g, k, prefix) for g in model.loads
              for prefix in {"ACMTBLU1": ("",), **dict.fromkeys(COMPOSITE, ("d_",))}.get(
                  g.model.name, ()) for k in range(len(g.index))]
    motor_bus = np.array([model.bus_numbers[model.load_bus[g.index[k]]] for g, k, _ in groups])
    runs = []
    vm_all = np.asarray(traj.vm)
    for i in range(len(faults)):
        flags = []
        for g, k, prefix in groups:
            p, keys = _motor_d(g, k, prefix)
            z = {name[len(prefix):]: np.asarray(traj.load_flags[model.loads.index(g)][name])
                 [i][:, k] for name in keys}
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
    """Th1t (p.u.) of each A/C motor (ACMTBLU1, a composite's motor D) by RAW bus number
    (a composite load's: its load bus)."""
    key = {"ACMTBLU1": "th1t", **dict.fromkeys(COMPOSITE, "d_th1t")}
    return {model.bus_numbers[model.load_bus[slot]]:
            float(np.asarray(g.params[key[g.model.name]])[k])
            for g in model.loads if g.model.name in key for k, slot in enumerate(g.index)}


def against(setup: Setup, cases: list[tuple[Fault, Run]], workdir: Path,
            model: GridModel | None = None, t_end: float | None = None) -> list[dict]:
    """[(`compare` dict, jaxgrid's Run)] of jaxgrid (one batch of the faults, sampled as the
    references) against each reference Run, up to t_end (s; default the setup's); jaxgrid's
    model compiled from the setup's files with the default options, unless given."""
    if model is None:
        model = jaxgrid_model(setup, edited_dyr(setup.dyr, setup.edit, workdir / "edited.dyr"))
    t_end = setup.t_end if t_end is None else t_end
    cases = [(fault, ref.until(t_end)) for fault, ref in cases]
    buses = sorted({int(b) for _, ref in cases for b in ref.bus_ids} & set(model.bus_numbers))
    step = cases[0][1].t[1] - cases[0][1].t[0]
    ours = run_jaxgrid(model, [fault for fault, _ in cases], t_end, setup.dt, buses,
                       max(1, round(step / setup.dt)))
    th1t = motor_th1t(model)
    return [(compare(ref, run, fault, th1t), run) for (fault, ref), run in zip(cases, ours)]


def against_saved(paths, workdir: Path, t_end: float | None = None) -> list[tuple[str, dict]]:
    """[(file name, `compare` dict)] of jaxgrid against saved references (`save_reference`
    files), one jaxgrid batch per setup, up to t_end (s; default each setup's)."""
    groups: dict = {}
    for path in sorted(Path(p) for p in paths):
        run, fault, setup = load_reference(path)
        groups.setdefault(setup, []).append((path.name, fault, run))
    out = []
    for setup, cases in groups.items():
        rows = against(setup, [(fault, run) for _, fault, run in cases], workdir, t_end=t_end)
        out += [(name, row) for (name, _, _), (row, _) in zip(cases, rows)]
    return out


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
