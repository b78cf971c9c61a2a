"""A load-shedding study as one value: operating points, buses, reward, steps and task sets.

    study = load_study("ieee39_fidvr")                  # built-in, load levels as points
    study = load_study("studies/ieee39_pnnl.toml")      # the project's study file
    study = from_files(["a.raw", "b.raw"], "x.dyr", "task.json", "sim.json")
    other = read_study("studies/ieee39_pnnl.toml", raw=["c.raw"])  # its settings at c.raw
    env, grid = study.env(), study.point(0)
    write_study(study, "run/study.toml")                # a run folder alone reproduces it

A `Study` holds its `StudyDefinition` (everything that rebuilds it, serialisable to TOML),
the operating points (solved cases of one grid) and their compiled models stacked into
one `GridModel` pytree with a leading operating-point axis (`models`). That pytree is data:
it is passed to compiled functions as an argument (`jaxgrid.problem.at_point` selects a
point inside jit), so one compilation serves every operating point of the grid.

Built three ways:
  built-in: `jaxgrid.cases` FIDVR study cases ("ieee39_fidvr", "ieee300_fidvr") at one or
    more load levels; buses, step, reward values and task sets are the case's.
  from files: RAW files (the operating points; one grid, so bus, branch, load and machine
    structure must agree; the first again at `base_load_levels`, factors on its loads and
    dispatch), one DYR, optionally a PNNL task JSON (buses, reward, history,
    training faults: `jaxgrid.study.pnnl`) and a PNNL simulation JSON (step, episode length).
  study file (TOML, `read_study`): names the built-in or the files (paths relative to the
    file, RAW paths may be glob patterns) and overrides any field of the definition:

        name = "ieee39_pnnl"
        [grid]      builtin, load_levels | raw, base_load_levels, dyr, task_config, sim_config
        [compile]   strict, precision, sweeps (the solver's), [compile.motors], [compile.loads]
        [env]       jaxgrid.env.EnvConfig fields (observed_buses, action_buses, agent_dt,
                    episode, history, include_action_status, recovery_buses, [env.bounds])
                    and its solver's (jaxgrid.steppers.Solver: dt, coarse_dt, fine_window,
                    coarse_sweeps, motor_step)
        [params]    jaxgrid.env.EnvParams fields (reward weights, action range, recovery)
        [tasks.NAME] jaxgrid.tasks.TaskSet fields (fault_buses, fault_durations,
                    fault_starts, operating_points, fault_r, fault_x)
        [training]  TrainingSettings fields (history = {lstm = 1, ...}, task_sampling)

`write_study` writes the resolved definition, every field explicit and paths absolute;
reading it back gives the identical definition.

The package, by idea: `definition` (the values: `StudyDefinition`, `Study`, ...),
`sources` (what a built-in or a set of files gives: one `SourceDefaults` each), `pnnl`
(the PNNL task and simulation JSON readers), `names` (PNNL bus names), `build` (the
definition from a source and overrides, each point's power flow, compile, stacking) and
`toml` (the study-file codec).
"""
from __future__ import annotations

from jaxgrid.study.build import builtin, from_files, rebuild
from jaxgrid.study.definition import (CompileSettings, GridSource, OperatingPoint, Study,
                                      StudyDefinition, StudyWarning, TrainingSettings)
from jaxgrid.study.names import BusTable, bus_number
from jaxgrid.study.toml import load_study, read_study, write_study

__all__ = ["BusTable", "CompileSettings", "GridSource", "OperatingPoint", "Study",
           "StudyDefinition", "StudyWarning", "TrainingSettings", "builtin", "bus_number",
           "from_files", "load_study", "read_study", "rebuild", "write_study"]
