"""Task sets of the PARS study and task configuration files.

A task is data: fault bus, start, duration, impedance and operating point (`TaskSpec`).
`task_set(name)` gives the study's named sets, `study_task_set(case, "train" | "test")` those
of a built-in study case; `task_batch(model, specs)` turns specs of
one operating point into a stacked `simulate.Task` for a vmapped rollout.

`read_task_config(path, case)` reads the original PNNL task files (RLGC/HADREC JSON with
keys such as observationWeight, actionPenalty, minVoltRecoveryLevel, faultBusCandidates)
and the project's own format (the same content under `EnvParams` / `EnvConfig` field
names: see `OWN_KEYS`), and returns a `TaskConfig`.
"""
from __future__ import annotations

import dataclasses
import itertools
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from jaxgrid.case import Case
from jaxgrid.env import EnvParams
from jaxgrid.grid import GridModel
from jaxgrid.simulate import FaultEvent, Task, make_task, stack_tasks


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """One disturbance of the study.

    Attributes:
      fault_bus: RAW bus number.  fault_duration: s (0: no fault).  fault_start: s.
      operating_point: load level of the case (1.0 = base).
      fault_r, fault_x: fault impedance, p.u. system base (default bolted).
    """

    fault_bus: int
    fault_duration: float
    fault_start: float = 1.0
    operating_point: float = 1.0
    fault_r: float = 0.0
    fault_x: float = 1e-4

    def event(self) -> FaultEvent | None:
        """The FaultEvent, or None for a zero-duration fault."""
        if self.fault_duration <= 0:
            return None
        return FaultEvent(self.fault_bus, self.fault_start, self.fault_duration, self.fault_r,
                          self.fault_x)


def grid_of(buses: Sequence[int], durations: Sequence[float],
            operating_points: Sequence[float] = (1.0,), start: float = 1.0) -> list[TaskSpec]:
    """Every fault bus × duration × operating point."""
    return [TaskSpec(b, d, start, op)
            for op, b, d in itertools.product(operating_points, buses, durations)]


# The study's sets (PNNL task files; the 300-bus test buses are those of the testing file
# plus bus 26 of the training set: 34 zone-1 buses).
ZONE1_TEST_BUSES_300 = (3, 5, 12, 2, 8, 15, 17, 23, 1, 4, 6, 7, 9, 10, 11, 13, 14, 16, 19, 20,
                        21, 22, 25, 87, 102, 89, 125, 160, 320, 150, 123, 131, 130, 26)
TASK_SETS = {
    "ieee39_train": ((4, 15, 21), (0.0, 0.05, 0.08)),
    "ieee39_test": (tuple(range(1, 31)), (0.02, 0.05, 0.08, 0.1)),
    "ieee300_train": ((2, 3, 5, 8, 12, 15, 17, 23, 26), (0.0, 0.05, 0.08)),
    "ieee300_test": (ZONE1_TEST_BUSES_300, (0.05, 0.06, 0.07, 0.08, 0.1)),
}


def task_set(name: str, operating_points: Sequence[float] = (1.0,)) -> list[TaskSpec]:
    """A named task set of the study (TASK_SETS), optionally over several operating points."""
    if name not in TASK_SETS:
        raise ValueError(f"unknown task set {name!r}; known: {', '.join(TASK_SETS)}")
    buses, durations = TASK_SETS[name]
    return grid_of(buses, durations, operating_points)


def study_task_set(case: str, split: str,
                   operating_points: Sequence[float] = (1.0,)) -> list[TaskSpec]:
    """The study's "train" or "test" set of a built-in study case ("ieee39_fidvr" ->
    TASK_SETS["ieee39_train"] / ["ieee39_test"])."""
    name = f"{case.removesuffix('_fidvr')}_{split}"
    if not case.endswith("_fidvr") or name not in TASK_SETS:
        raise ValueError(f"case {case!r} has no default task set {split!r} (known: the "
                         "cases ieee39_fidvr and ieee300_fidvr, the sets train and test)")
    return task_set(name, operating_points)


def task_batch(model: GridModel, specs: Sequence[TaskSpec]) -> Task:
    """Stacked Task (leading axis) of specs that share one operating point."""
    points = {s.operating_point for s in specs}
    if len(points) != 1:
        raise ValueError(f"task_batch: specs span operating points {sorted(points)}; "
                         "batch each operating point with its own model")
    return stack_tasks([make_task(model, s.event()) for s in specs])


# --------------------------------------------------------------------------- #
# Task configuration files
# --------------------------------------------------------------------------- #

@dataclasses.dataclass(frozen=True)
class TaskConfig:
    """A task configuration read from a file.

    Attributes:
      params: reward and action values.  observed_buses, action_buses: RAW numbers.
      agent_dt: control step, s.  history: observations stacked.
      fault_buses, fault_durations (s), fault_starts (s): the candidates.
      source: the file.
    """

    params: EnvParams
    observed_buses: tuple[int, ...]
    action_buses: tuple[int, ...]
    agent_dt: float
    history: int
    fault_buses: tuple[int, ...]
    fault_durations: tuple[float, ...]
    fault_starts: tuple[float, ...]
    source: str

    def tasks(self, operating_points: Sequence[float] = (1.0,)) -> list[TaskSpec]:
        """Every candidate fault bus × duration × start × operating point."""
        return [TaskSpec(b, d, s, op) for op, s, b, d in itertools.product(
            operating_points, self.fault_starts, self.fault_buses, self.fault_durations)]


# The project's own format: these keys, the EnvParams field names, and nothing else.
OWN_KEYS = ("observed_buses", "action_buses", "agent_dt", "history", "fault_buses",
            "fault_durations", "fault_starts")


def read_task_config(path: str | Path, case: Case | None = None) -> TaskConfig:
    """A TaskConfig from a PNNL task JSON or the project's own JSON.

    `case` resolves a zone-wide observation scope of the PNNL files (observed buses: the
    zone's buses above observationVoltThreshold volts, plus the action buses). Errors name
    the file and the key.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: cannot read a task configuration: {err}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a task configuration must be a JSON object")
    if "observationScopeType" in data:
        return _from_pnnl(data, path, case)
    return _from_own(data, path)


def _require(data: dict, key: str, path: Path):
    if key not in data:
        raise ValueError(f"{path}: missing key {key!r}")
    return data[key]


def _bus_numbers(values, path: Path, key: str) -> tuple[int, ...]:
    """RAW numbers from PNNL names such as 'Bus504' or 'bus20001', or plain integers."""
    out = []
    for v in values:
        text = str(v).strip().lower().removeprefix("bus")
        if not text.isdigit():
            raise ValueError(f"{path}: {key}: {v!r} is not a bus ('Bus<number>')")
        out.append(int(text))
    return tuple(out)


def _from_pnnl(data: dict, path: Path, case: Case | None) -> TaskConfig:
    action = _bus_numbers(_require(data, "actionScopeAry", path), path, "actionScopeAry")
    scope = _require(data, "observationScopeType", path)
    if scope == "Bus":
        observed = _bus_numbers(_require(data, "observationScopeAry", path), path,
                                "observationScopeAry")
    elif scope == "Zone":
        if case is None:
            raise ValueError(f"{path}: observationScopeType 'Zone' needs the case to list "
                             "the zone's buses (read_task_config(path, case))")
        threshold_kv = float(data.get("observationVoltThreshold", 0.0)) / 1000.0
        zones = [int(z) for z in _require(data, "observationScopeAry", path)]
        chosen = [int(case.buses.number[b]) for z in zones for b in case.buses_in_zone(z)
                  if case.buses.base_kv[b] > threshold_kv]
        observed = tuple(chosen + [b for b in action if b not in chosen])
    else:
        raise ValueError(f"{path}: observationScopeType {scope!r}: allowed 'Bus' or 'Zone'")
    ranges = np.asarray(_require(data, "actionValueRanges", path), dtype=float)
    lows, highs = set(ranges[:, 0]), set(ranges[:, 1])
    if len(lows) != 1 or len(highs) != 1:
        raise ValueError(f"{path}: actionValueRanges: one range for every action bus expected")
    params = EnvParams(
        c_voltage=float(_require(data, "observationWeight", path)),
        c_shed=float(_require(data, "actionPenalty", path)),
        c_invalid=float(_require(data, "invalidActionPenalty", path)),
        c_prefault=float(_require(data, "preFaultActionPenalty", path)),
        unstable_penalty=-float(_require(data, "unstableReward", path)),
        recovery_level=float(_require(data, "minVoltRecoveryLevel", path)),
        recovery_time=float(_require(data, "maxVoltRecoveryTime", path)),
        action_low=float(lows.pop()), action_high=float(highs.pop()))
    return TaskConfig(
        params=params, observed_buses=observed, action_buses=action,
        agent_dt=float(_require(data, "envStepTimeInSec", path)),
        history=int(data.get("historyObservationSize", 1)),
        fault_buses=_bus_numbers(_require(data, "faultBusCandidates", path), path,
                                 "faultBusCandidates"),
        fault_durations=tuple(float(d) for d in _require(data, "faultDurationCandidates", path)),
        fault_starts=tuple(float(s) for s in data.get("faultStartTimeCandidates", [1.0])),
        source=str(path))


def _from_own(data: dict, path: Path) -> TaskConfig:
    param_names = {f.name for f in dataclasses.fields(EnvParams)}
    unknown = sorted(set(data) - param_names - set(OWN_KEYS))
    if unknown:
        raise ValueError(f"{path}: unknown keys {unknown}; allowed: "
                         f"{sorted(param_names | set(OWN_KEYS))}")
    params = EnvParams(**{k: float(v) for k, v in data.items() if k in param_names})
    return TaskConfig(
        params=params,
        observed_buses=_bus_numbers(_require(data, "observed_buses", path), path,
                                    "observed_buses"),
        action_buses=_bus_numbers(_require(data, "action_buses", path), path, "action_buses"),
        agent_dt=float(data.get("agent_dt", 0.1)), history=int(data.get("history", 1)),
        fault_buses=_bus_numbers(_require(data, "fault_buses", path), path, "fault_buses"),
        fault_durations=tuple(float(d) for d in _require(data, "fault_durations", path)),
        fault_starts=tuple(float(s) for s in data.get("fault_starts", [1.0])),
        source=str(path))
