"""The values a study is: its definition (what rebuilds it, what a study file holds) and
the built `Study` (module docstring of `jaxgrid.study`).

`StudyDefinition` is the one definition of a study: `GridSource` (where the operating points
come from), `CompileSettings`, the environment's `EnvConfig` and `EnvParams`, named
`TaskSet`s and `TrainingSettings`. `Study` holds it with the operating points and their
compiled models stacked (`jaxgrid.study.build`).
"""
from __future__ import annotations

import dataclasses
import math

import jax

from jaxgrid.case import Case
from jaxgrid.checks import InputError, Range, check_each, check_int, check_listed, check_unique
from jaxgrid.compile import MACHINE_BASE_RULES
from jaxgrid.env import HISTORY, EnvConfig, EnvParams, LoadSheddingEnv
from jaxgrid.grid import GridModel
from jaxgrid.models.acmotor import MotorOptions
from jaxgrid.models.cmld import CompositeOptions
from jaxgrid.models.loads import LoadSplit
from jaxgrid.powerflow import PowerFlowResult
from jaxgrid.study.names import BusTable
from jaxgrid.tasks import PointTask, TaskSet, TaskSpec, task_batch


class StudyWarning(UserWarning):
    """A study input that is read but changes nothing, or a check that does not match."""


@dataclasses.dataclass(frozen=True)
class GridSource:
    """Where the operating points come from: a built-in case or files (absolute paths).

    Attributes:
      builtin: a `jaxgrid.cases` FIDVR study case name, or None.
      load_levels: the built-in's operating points (factor on loads and dispatch).
      raw: RAW files, one per operating point.  dyr: the DYR file.
      base_load_levels: more operating points of a study from files, after the RAW files':
        the first RAW file with every load and generator P dispatch times each factor
        (`jaxgrid.case.at_load_level`) and the units' reactive limits widened to what that
        needs, as the PNNL `baseCases` "scalepercent" files are made.
      task_config, sim_config: PNNL task and simulation JSON files, or None.
    """

    builtin: str | None = None
    load_levels: tuple[float, ...] = (1.0,)
    raw: tuple[str, ...] = ()
    base_load_levels: tuple[float, ...] = ()
    dyr: str | None = None
    task_config: str | None = None
    sim_config: str | None = None

    def __post_init__(self):
        """InputError naming the field of a bad value, or of one the source would not read
        (files with a built-in, load levels with RAW files)."""
        check_listed("load_levels", self.load_levels, "load level")
        check_each("load_levels", self.load_levels, LOAD_LEVEL)
        check_unique("raw", self.raw)  # one file twice would be one operating point twice
        check_unique("base_load_levels", self.base_load_levels)
        check_each("base_load_levels", self.base_load_levels, LOAD_LEVEL)
        files = {k: v for k, v in (("raw", self.raw), ("base_load_levels", self.base_load_levels),
                                   ("dyr", self.dyr), ("task_config", self.task_config),
                                   ("sim_config", self.sim_config)) if v}
        if self.builtin and files:
            raise InputError("builtin", self.builtin, f"a built-in study reads no files: leave "
                             f"out {', '.join(files)}, or builtin for a study from files")
        if self.raw and tuple(self.load_levels) != (1.0,):
            raise InputError("load_levels", list(self.load_levels), "set a built-in study's "
                             "operating points; a study from files has one per RAW file and "
                             "per base_load_levels factor")


LOAD_LEVEL = Range(0.0, 10.0, "(factor on loads and dispatch)", lo_open=True)
PRECISIONS = ("float32", "float64")  # CompileSettings.precision (the time loop's)


@dataclasses.dataclass(frozen=True)
class CompileSettings:
    """How every operating point is compiled (`jaxgrid.compile.CompileOptions`; the action
    buses become the load slots). How the points are integrated is the environment's
    solver (`EnvConfig.solver`; a study file writes its sweeps in [compile])."""

    strict: bool = True
    precision: str = "float32"
    machine_base: str = "gridpack"
    motors: MotorOptions = MotorOptions()
    loads: LoadSplit = LoadSplit()
    composite: CompositeOptions = CompositeOptions()

    def __post_init__(self):
        """InputError naming the field of a value `CompileOptions` does not take, or of a
        non-finite number in an option table ("motors.stiff_below")."""
        for name, allowed in (("precision", PRECISIONS), ("machine_base", MACHINE_BASE_RULES)):
            if getattr(self, name) not in allowed:
                raise InputError(name, getattr(self, name), f"must be one of {list(allowed)}")
        for table in ("motors", "loads", "composite"):
            options = getattr(self, table)
            for field in dataclasses.fields(options):
                value = getattr(options, field.name)
                if isinstance(value, float) and not math.isfinite(value):
                    raise InputError(f"{table}.{field.name}", value, "must be finite")


POLICY_KINDS = ("linear", "fnn", "lstm")
# The PARS study's inputs per policy kind: 10 stacked observations for linear and FNN
# policies, the current one for the LSTM (it remembers the rest); built-in studies train so.
PAPER_HISTORY = {"linear": 10, "fnn": 10, "lstm": 1}
TASK_SAMPLINGS = ("uniform", "stratified")


@dataclasses.dataclass(frozen=True)
class TrainingSettings:
    """How the study's policies train where the study fixes it (`experiments.train` takes
    these as its flag defaults).

    Attributes:
      history: {policy kind: observations stacked}; a kind not named stacks env.history.
      task_sampling: "uniform" (m distinct tasks) or "stratified"
        (`jaxgrid.problem.stratified_sampler`).
    """

    history: dict = dataclasses.field(default_factory=dict)
    task_sampling: str = "uniform"

    def __post_init__(self):
        """InputError naming the field ("history.lstm") of a bad value."""
        for kind, stacked in self.history.items():
            if kind not in POLICY_KINDS:
                raise InputError(f"history.{kind}", stacked, f"{kind!r} is not a policy kind "
                                 f"({', '.join(POLICY_KINDS)})")
            check_int(f"history.{kind}", stacked, HISTORY)
        if self.task_sampling not in TASK_SAMPLINGS:
            raise InputError("task_sampling", self.task_sampling,
                             f"must be one of {list(TASK_SAMPLINGS)}")


@dataclasses.dataclass(frozen=True)
class StudyDefinition:
    """Everything that rebuilds a study (what `write_study` saves).

    Attributes:
      name: the study's name.  grid: its sources.  compile: compile settings.
      env: the environment's structure.  params: reward and action values.
      tasks: named task sets ("train", "test", ...).  training: TrainingSettings.
    """

    name: str
    grid: GridSource
    compile: CompileSettings
    env: EnvConfig
    params: EnvParams
    tasks: dict
    training: TrainingSettings = TrainingSettings()


@dataclasses.dataclass(frozen=True)
class OperatingPoint:
    """One solved case of the study's grid.

    Attributes:
      label: short name ("load100", a RAW file's stem).  source: where it came from.
      case: the network.  power_flow: its solution, the compiled model's initial point.
      notes: what the compiler reported for it (load report, ...).
    """

    label: str
    source: str
    case: Case
    power_flow: PowerFlowResult
    notes: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class Study:
    """A load-shedding study (`jaxgrid.study`).

    Attributes:
      definition: what rebuilds it.  points: the operating points.
      models: the compiled points stacked, every array leaf with a leading (n_points,) axis.
      buses: the names study files can use for its buses
        (`jaxgrid.study.names.bus_number`).
      notes: what the readers and checks reported (unused keys, count mismatches, ...).
    """

    definition: StudyDefinition
    points: tuple[OperatingPoint, ...]
    models: GridModel
    buses: BusTable
    notes: tuple[str, ...]

    @property
    def name(self) -> str:
        return self.definition.name

    @property
    def config(self) -> EnvConfig:
        return self.definition.env

    @property
    def params(self) -> EnvParams:
        return self.definition.params

    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def base_mva(self) -> float:
        return self.points[0].case.base_mva

    def point(self, index: int) -> GridModel:
        """The compiled model of operating point `index` (host arrays)."""
        return jax.tree.map(lambda a: a[index], self.models)

    def history(self, policy_kind: str) -> int:
        """Observations a `policy_kind` policy stacks in this study's training."""
        return self.definition.training.history.get(policy_kind, self.config.history)

    def env(self, **config) -> LoadSheddingEnv:
        """The environment; `config` overrides EnvConfig or solver fields, e.g. episode=6.0
        (s), sweeps=4 (`EnvConfig.replace`)."""
        return LoadSheddingEnv(self.point(0), self.config.replace(**config))

    def task_set(self, name: str) -> TaskSet:
        """The named task set; ValueError listing the study's sets."""
        if name not in self.definition.tasks:
            raise ValueError(f"study {self.name!r} has no task set {name!r}; it has "
                             f"{', '.join(sorted(self.definition.tasks)) or 'none'}")
        return self.definition.tasks[name]

    def tasks(self, name: str) -> list[TaskSpec]:
        """The specs of the named task set (every operating point × fault × duration), or of
        several joined by "+" ("train+train_extra": theirs in that order)."""
        return [s for part in name.split("+") for s in self.task_set(part).specs(self.n_points)]

    def batch(self, specs) -> PointTask:
        """Stacked PointTask of specs (any operating points of this study)."""
        return task_batch(self.point(0), specs)
