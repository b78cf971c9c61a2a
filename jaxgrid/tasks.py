"""Task sets of a load-shedding study: operating point × fault bus × start × duration.

A task is data: the operating point (an index into the study's points), fault bus, start,
duration and impedance (`TaskSpec`). A `TaskSet` is the product grid of candidates a study
names ("train", "test", ...); `task_batch(model, specs)` turns specs into a stacked
`PointTask` (operating-point index + `simulate.Task`) for one vmapped, compiled rollout
over any mix of operating points of one grid.
"""
from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence

import numpy as np
from flax import struct

from jaxgrid.checks import InputError, Range, check_each, check_listed
from jaxgrid.grid import GridModel
from jaxgrid.simulate import FaultEvent, Task, make_task, stack_tasks


FAULT_TIME = Range(0.0, 3600.0, "s")
FAULT_IMPEDANCE = Range(0.0, 1e6, "p.u.")


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """One disturbance of the study.

    Attributes:
      fault_bus: RAW bus number.  fault_duration: s (0: no fault).  fault_start: s.
      operating_point: index into the study's operating points.
      fault_r, fault_x: fault impedance, p.u. system base (default bolted).
    """

    fault_bus: int
    fault_duration: float
    fault_start: float = 1.0
    operating_point: int = 0
    fault_r: float = 0.0
    fault_x: float = 1e-4

    def event(self) -> FaultEvent | None:
        """The FaultEvent, or None for a zero-duration fault."""
        if self.fault_duration <= 0:
            return None
        return FaultEvent(self.fault_bus, self.fault_start, self.fault_duration, self.fault_r,
                          self.fault_x)


@dataclasses.dataclass(frozen=True)
class TaskSet:
    """Every operating point × fault bus × start × duration of the candidates.

    Attributes:
      fault_buses: RAW bus numbers.  fault_durations, fault_starts: s.
      operating_points: indices into the study's points (None: all of them).
      fault_r, fault_x: fault impedance, p.u. system base.
    """

    fault_buses: tuple[int, ...]
    fault_durations: tuple[float, ...]
    fault_starts: tuple[float, ...] = (1.0,)
    operating_points: tuple[int, ...] | None = None
    fault_r: float = 0.0
    fault_x: float = 1e-4

    def __post_init__(self):
        """InputError naming the field (and entry) of a value outside its range, and of a
        list that is empty or repeats an entry (a repeat would double its tasks' weight)."""
        check_listed("fault_buses", self.fault_buses, "bus")
        check_listed("fault_durations", self.fault_durations, "duration (0: no fault)")
        check_listed("fault_starts", self.fault_starts, "start time")
        check_each("fault_durations", self.fault_durations, FAULT_TIME)
        check_each("fault_starts", self.fault_starts, FAULT_TIME)
        if self.operating_points is not None:
            check_listed("operating_points", self.operating_points, "operating point, or "
                         "leave it out for all of them")
        FAULT_IMPEDANCE.check("fault_r", self.fault_r)
        FAULT_IMPEDANCE.check("fault_x", self.fault_x)

    def points(self, n_points: int) -> tuple[int, ...]:
        """The operating-point indices of the set; InputError "operating_points" for an index
        the study's n_points do not have."""
        if self.operating_points is None:
            return tuple(range(n_points))
        bad = [p for p in self.operating_points if not 0 <= p < n_points]
        if bad:
            raise InputError("operating_points", list(self.operating_points),
                             f"the study has {n_points} operating point(s), indices 0 to "
                             f"{n_points - 1}")
        return self.operating_points

    def specs(self, n_points: int) -> list[TaskSpec]:
        """Every task, operating point outermost, then start, bus and duration."""
        return [TaskSpec(b, d, s, p, self.fault_r, self.fault_x) for p, s, b, d in
                itertools.product(self.points(n_points), self.fault_starts, self.fault_buses,
                                  self.fault_durations)]


@struct.dataclass
class PointTask:
    """A task as arrays: its operating point and its disturbance (a batch adds a leading axis).

    Attributes:
      point: () int index into the study's operating points.  task: the `simulate.Task`.
      quiet: () bool, the task recovers without control (a training label,
        `jaxgrid.problem.training_problem`'s c_quiet), or None where no one asked.
      reference_reward: () the reward a reference controller (UVLS) earns on the task (a
        training label, `training_problem`'s c_beat), or None where no one asked.
    """

    point: np.ndarray
    task: Task
    quiet: np.ndarray | None = None
    reference_reward: np.ndarray | None = None


def task_batch(model: GridModel, specs: Sequence[TaskSpec]) -> PointTask:
    """Stacked PointTask (leading axis) of specs; `model` is any operating point of the grid."""
    if not specs:
        raise ValueError("task_batch: no tasks")
    return PointTask(point=np.array([s.operating_point for s in specs], dtype=np.int32),
                     task=stack_tasks([make_task(model, s.event()) for s in specs]))
