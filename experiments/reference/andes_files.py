"""ANDES (CURENT, PyPI `andes`) beside jaxgrid: a run of the same RAW and DYR files with one
bus fault (`run_andes`), the DYR without what ANDES does not read (`write_psse_dyr`), and the
errors of a jaxgrid trajectory against it (`trajectory_errors`). Used by the validation tests,
the simulation benchmark and the command `experiments.reference.andes`.

ANDES reads the same PSS/E RAW and DYR files; its `Toggle` records are not part of PSS/E and
must not be in the DYR. ANDES converts constant-power loads to constant impedance in
time-domain simulation by default (`PQ.config.p2z = q2z = 1`), which matches `LoadSplit()`'s
default. ANDES 2.0's DYR reader takes the values of ESST1A and ESAC1A records in another
order than PSS/E's (andes/io/psse-dyr.yaml; measured for ESST1A: PSS/E's TC lands in its TB,
KA in VAMAX, VRMAX in ILR, ...), so `run_andes` hands it a copy with those records in its own
order (`andes_dyr`).
"""
from __future__ import annotations

import dataclasses
import logging
import os
import re
import time

import numpy as np

from experiments.reference.errors import at_times, deviation
from jaxgrid.models.exciters import Esac1a, Esst1a

# Models whose DYR values ANDES 2.0 reads in another order than PSS/E's (ESST1A measured:
# its TB gets PSS/E's TC, VAMAX gets KA, ...; ESAC1A by its psse-dyr.yaml: VAMAX gets KA, ...)
REORDERED = {m.name: m for m in (Esst1a, Esac1a)}


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
    ss = andes.load(raw, addfile=andes_dyr(dyr), setup=False, no_output=True,
                    default_config=True)
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


def andes_dyr(dyr: str) -> str:
    """`dyr` itself, or where it has records of a model in REORDERED a copy beside it
    (suffix `.andes.dyr`) whose records of those models list their values in the order
    ANDES's DYR reader assigns them (its psse-dyr.yaml `inputs`) instead of PSS/E's (the
    model's stored ICONs, then its CONs)."""
    import andes
    import yaml

    with open(dyr) as f:
        records = f.read().split("/")
    present = {_model(r) for r in records[:-1]} & set(REORDERED)
    if not present:
        return dyr
    with open(os.path.join(os.path.dirname(andes.__file__), "io", "psse-dyr.yaml")) as f:
        table = yaml.safe_load(f)
    orders = {}
    for name in present:
        inputs = table[name]["inputs"][2:]  # after BUS, ID
        model = REORDERED[name]
        psse = [*(n.upper() for n in model.stored_icons), *(c.name.upper() for c in model.cons)]
        assert sorted(inputs) == sorted(psse), f"ANDES's {name} inputs {inputs} are not {psse}"
        orders[name] = (psse, inputs)

    def reordered(record: str) -> str:
        name = _model(record)
        if name not in orders:
            return record
        psse, inputs = orders[name]
        before, after = re.split(rf"'\s*{name}\s*'", record, maxsplit=1)
        device_id, *values = after.split()
        by_name = dict(zip(psse, values))
        return f"{before}'{name}' {device_id} " + " ".join(by_name[n] for n in inputs) + " "

    target = os.path.splitext(dyr)[0] + ".andes.dyr"
    with open(target, "w") as f:
        f.write("/".join(reordered(r) for r in records[:-1]) + "/\n")
    return target


def _model(record: str) -> str:
    """The (quoted) model name of a DYR record's text, upper case, or ''."""
    quoted = re.search(r"'\s*([^'\s]+)\s*'", record)
    return quoted.group(1).upper() if quoted else ""


def write_psse_dyr(source: str, target: str, drop_models: tuple[str, ...] = ()) -> str:
    """Copy a DYR file without ANDES-only `Toggle` records and without `drop_models` records.

    Records end at '/'; a record is dropped when its model name (quoted) is listed, or
    "MODEL@BUS" with its bus number (the record's first field). Returns `target`.
    """
    with open(source) as f:
        records = f.read().split("/")
    drop = {m.upper() for m in drop_models} | {"TOGGLE"}

    def dropped(record: str) -> bool:
        fields = record.split()
        return bool({_model(record), f"{_model(record)}@{fields[0] if fields else ''}"} & drop)

    keep = [r for r in records[:-1] if not dropped(r)]
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
