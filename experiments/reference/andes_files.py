"""ANDES (CURENT, PyPI `andes`) beside jaxgrid: a run of the same RAW and DYR files with one
bus fault (`run_andes`), the DYR without what ANDES does not read (`write_psse_dyr`), and the
errors of a jaxgrid trajectory against it (`trajectory_errors`). Used by the validation tests,
the simulation benchmark and the command `experiments.reference.andes`.

ANDES reads the same PSS/E RAW and DYR files; its `Toggle` records are not part of PSS/E and
must not be in the DYR. ANDES converts constant-power loads to constant impedance in
time-domain simulation by default (`PQ.config.p2z = q2z = 1`), which matches `LoadSplit()`'s
default.
"""
from __future__ import annotations

import dataclasses
import logging
import re
import time

import numpy as np

from experiments.reference.errors import at_times, deviation


@dataclasses.dataclass(frozen=True)
class AndesRun:
    """ANDES results. t (n_t,) s; vm, va (n_t, n_bus) p.u./rad for `bus_ids`; speed_dev,
    angle (n_t, n_gen) p.u./rad for machines at `gen_bus`; wall time of TDS in s."""

    t: np.ndarray
    bus_ids: np.ndarray
    vm: np.ndarray
    va: np.ndarray
    gen_bus: np.ndarray
    speed_dev: np.ndarray
    angle: np.ndarray
    wall_s: float


def run_andes(raw: str, dyr: str, t_end: float, fault_bus: int | None = None,
              fault_start: float = 1.0, fault_duration: float = 0.1, fault_x: float = 1e-4,
              tstep: float = 0.005) -> AndesRun:
    """Time-domain simulation in ANDES (implicit trapezoid, fixed step `tstep`, s)."""
    import andes

    andes.config_logger(stream_level=logging.ERROR)
    ss = andes.load(raw, addfile=dyr, setup=False, no_output=True, default_config=True)
    if fault_bus is not None:
        ss.add("Fault", {"bus": fault_bus, "tf": fault_start,
                         "tc": fault_start + fault_duration, "xf": fault_x, "rf": 0.0})
    ss.setup()
    ss.PFlow.run()
    ss.TDS.config.tf = t_end
    ss.TDS.config.tstep = tstep
    ss.TDS.config.fixt = 1
    ss.TDS.config.no_tqdm = 1
    start = time.perf_counter()
    ss.TDS.run()
    wall = time.perf_counter() - start
    ts = ss.dae.ts
    machines = [m for m in (ss.GENROU, ss.GENCLS) if m.n]
    return AndesRun(
        t=np.asarray(ts.t), bus_ids=np.asarray(ss.Bus.idx.v),
        vm=np.asarray(ts.y[:, ss.Bus.v.a]), va=np.asarray(ts.y[:, ss.Bus.a.a]),
        gen_bus=np.concatenate([np.asarray(m.bus.v) for m in machines]),
        speed_dev=np.concatenate([ts.x[:, m.omega.a] for m in machines], axis=1) - 1.0,
        angle=np.concatenate([ts.x[:, m.delta.a] for m in machines], axis=1),
        wall_s=wall)


def write_psse_dyr(source: str, target: str, drop_models: tuple[str, ...] = ()) -> str:
    """Copy a DYR file without ANDES-only `Toggle` records and without `drop_models` records.

    Records end at '/'; a record is dropped when its model name (quoted) is listed.
    Returns `target`.
    """
    with open(source) as f:
        records = f.read().split("/")
    drop = {m.upper() for m in drop_models} | {"TOGGLE"}

    def model(record: str) -> str:
        quoted = re.search(r"'\s*([^'\s]+)\s*'", record)
        return quoted.group(1).upper() if quoted else ""

    keep = [r for r in records[:-1] if model(r) not in drop]
    with open(target, "w") as f:
        f.write("/".join(keep) + "/\n")
    return target


@dataclasses.dataclass(frozen=True)
class Errors:
    """Errors of a trajectory against ANDES outside `settle` s after each event.

    v_max, v_rms: bus voltage magnitude, p.u.; speed: largest |Δω| error, p.u.;
    angle_deg: largest error of rotor angles relative to the first machine, degrees.
    """

    v_max: float
    v_rms: float
    speed: float
    angle_deg: float


def trajectory_errors(model, traj, ref: AndesRun, event_times, settle: float = 0.03) -> Errors:
    """A single-rollout `Trajectory` of `model` against `ref` by the harnesses' one measure
    (`experiments.reference.errors`): ANDES's run at the trajectory's times, every sample
    outside `settle` s after each event. ANDES's machines are matched to ours by bus, the
    k-th at a bus to the k-th here; angles are compared relative to the first machine."""
    t = np.asarray(traj.t)
    keep = np.all([(t < e - 1e-9) | (t >= e + settle) for e in event_times], axis=0)
    buses = [model.bus_numbers.index(b) for b in ref.bus_ids]
    v_max, v_rms = deviation(np.asarray(traj.vm)[:, buses], at_times(t, ref.t, ref.vm), keep)
    machines: list[int] = []
    for b in ref.gen_bus:
        machines.append(next(k for k, gb in enumerate(model.gen_bus)
                             if gb == b and k not in machines))
    speed, _ = deviation(np.asarray(traj.speed_dev)[:, machines],
                         at_times(t, ref.t, ref.speed_dev), keep)
    ours, theirs = np.asarray(traj.angle)[:, machines], at_times(t, ref.t, ref.angle)
    angle, _ = deviation(ours - ours[:, :1], theirs - theirs[:, :1], keep)
    return Errors(v_max=v_max, v_rms=v_rms, speed=speed, angle_deg=float(np.degrees(angle)))
