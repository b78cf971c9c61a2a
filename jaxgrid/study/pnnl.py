"""Readers of the PNNL PARS study's JSON files (RLGC / HADREC `testData/`).

`read_task_config(path)` reads a load-shedding task configuration (keys such as
observationWeight, actionScopeAry, faultBusCandidates) into a `PnnlTask`;
`read_sim_config(path)` reads a dynamic-simulation configuration (simuTimeStepSec,
totalSimuTimeSec, ...) into a `PnnlSimConfig`. Bus references stay as written ("Bus504",
"bus20001", "Bus20_loadBus"): the study resolves them against its grid
(`jaxgrid.study.sources`), which names the file, key and value of one that is missing.

Every key of the files under ../shared/cases is read and either used or reported in
`notes` with the reason it changes nothing here; a key this module does not know is
reported too (`unknown`), never dropped silently. A value of the wrong type raises a
`ValueError` naming the file, key and value.

Task keys and their use:
  observationScopeType/Ary, observationVoltThreshold (V): the observed buses ("Bus": the
    names; "Zone": the zones' buses above the threshold, then the action buses).
  actionScopeType/Ary: the action buses ("Bus": the names; "Zone": every bus with an
    in-service load in the zones).
  historyObservationSize, envStepTimeInSec, includeActionStatusInObservations: EnvConfig.
  observationWeight, actionPenalty, invalidActionPenalty, preFaultActionPenalty,
    unstableReward (negated), minVoltRecoveryLevel, maxVoltRecoveryTime,
    actionValueRanges (one range shared by all action buses, or one given once): EnvParams.
  faultBusCandidates, faultStartTimeCandidates, faultDurationCandidates: the training set.
  ObservationSelfZoneVoltNum, ObservationSelfZoneLowVoltNum, ObservationOtherZoneVoltNum,
    actionLoadSelfZoneNum, actionLoadOtherZoneNum, actionBusesPValue (MW): checks of the
    resolved buses and loads; a mismatch is a note of the study.
  observationStateTypes ["voltageMag"], actionTypes ["LoadShed"], actionSpaceType
    "continuous": checked (nothing else is implemented).
  version, environmentName (the study's default name), studyCaseFolder, actionLevels (the
    discrete action set, unused by the continuous action space): noted.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

from jaxgrid.checks import Range, check_each, check_unique
from jaxgrid.env import AGENT_DT, EPISODE, HISTORY, PARAM_RANGES, check_params
from jaxgrid.steppers import DT
from jaxgrid.tasks import FAULT_IMPEDANCE, FAULT_TIME

# PNNL key -> EnvParams field (unstableReward is negated: EnvParams holds the penalty M).
PARAM_KEYS = {"observationWeight": "c_voltage", "actionPenalty": "c_shed",
              "invalidActionPenalty": "c_invalid", "preFaultActionPenalty": "c_prefault",
              "unstableReward": "unstable_penalty", "minVoltRecoveryLevel": "recovery_level",
              "maxVoltRecoveryTime": "recovery_time"}
COUNT_KEYS = ("ObservationSelfZoneVoltNum", "ObservationSelfZoneLowVoltNum",
              "ObservationOtherZoneVoltNum", "actionLoadSelfZoneNum", "actionLoadOtherZoneNum")
_NOTED_TASK_KEYS = {
    "version": "file format version",
    "studyCaseFolder": "the original's folder of operating points; this study takes its RAW "
                       "files explicitly",
    "actionLevels": "the discrete action set, unused with actionSpaceType 'continuous'",
}
_TASK_KEYS = ({"environmentName", "observationStateTypes", "observationScopeType",
               "observationScopeAry", "observationVoltThreshold", "historyObservationSize",
               "actionTypes", "actionScopeType", "actionScopeAry", "envStepTimeInSec",
               "includeActionStatusInObservations", "faultBusCandidates",
               "faultStartTimeCandidates", "faultDurationCandidates", "actionSpaceType",
               "actionValueRanges", "actionBusesPValue"}
              | set(PARAM_KEYS) | set(COUNT_KEYS) | set(_NOTED_TASK_KEYS))

_NOTED_SIM_KEYS = {
    "dynamicFileName": "the original's DYR path; this study names its DYR file",
    "dstabOutputFileName": "the original's output file",
    "eventStartTimeSec": "a single event of the original's examples; faults come from the task "
                         "set",
    "eventDurationSec": "as eventStartTimeSec",
    "referenceGeneratorId": "angles here are in the network frame, not relative to a machine",
    "monitoringBusAry": "buses the original wrote out; trajectories here hold every bus",
    "monitoringGenAry": "machines the original wrote out; trajectories here hold every machine",
    "outputPerNSteps": "output decimation of the original",
}
_ACSC_USED = {"type", "category", "zLG"}


@dataclasses.dataclass(frozen=True)
class PnnlTask:
    """A PNNL load-shedding task configuration, bus references as written: the input of a
    study from files, turned into its defaults by `jaxgrid.study.sources.file_source`.

    Attributes:
      source: the file.  name: environmentName.
      observation_scope, action_scope: "Bus" or "Zone".
      observed, action: bus names (Bus scope) or zone numbers as strings (Zone scope).
      observed_min_kv: observationVoltThreshold in kV (Zone scope), else 0.
      history: historyObservationSize.  agent_dt: envStepTimeInSec, s.
      include_action_status: includeActionStatusInObservations.
      params: {EnvParams field: value}, including action_low / action_high.
      fault_buses: names.  fault_starts, fault_durations: s.
      counts: {count key: value} of the file's check counts (COUNT_KEYS) present.
      action_p_mw: actionBusesPValue (MW per action bus) or None.
      notes: keys read but not used, with the reason.  unknown: keys this reader does not know.
    """

    source: str
    name: str
    observation_scope: str
    observed: tuple[str, ...]
    observed_min_kv: float
    action_scope: str
    action: tuple[str, ...]
    history: int
    agent_dt: float
    include_action_status: bool
    params: dict
    fault_buses: tuple[str, ...]
    fault_starts: tuple[float, ...]
    fault_durations: tuple[float, ...]
    counts: dict
    action_p_mw: tuple[float, ...] | None
    notes: tuple[str, ...]
    unknown: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class PnnlSimConfig:
    """A PNNL dynamic-simulation configuration.

    Attributes:
      source: the file.  dt: simuTimeStepSec, s.  t_end: totalSimuTimeSec, s.
      fault_r, fault_x: fault impedance from acscConfigBean.zLG, p.u. (None: zero in the
        file, i.e. a bolted fault, which this simulator represents with its default).
      notes, unknown: as PnnlTask.
    """

    source: str
    dt: float
    t_end: float
    fault_r: float | None
    fault_x: float | None
    notes: tuple[str, ...]
    unknown: tuple[str, ...]


def _load(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: cannot read a JSON configuration: {err}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a configuration must be a JSON object")
    return data


class _Keys:
    """Typed access to one JSON object; errors name the file, key and value."""

    def __init__(self, data: dict, path: Path, prefix: str = ""):
        self.data, self.path, self.prefix = data, path, prefix

    def _bad(self, key, value, what):
        return ValueError(f"{self.path}: {self.prefix}{key} = {value!r}: must be {what}")

    def get(self, key, default=None, required=True):
        if key not in self.data:
            if required and default is None:
                raise ValueError(f"{self.path}: missing key {self.prefix}{key!r}")
            return default
        return self.data[key]

    def name(self, key) -> str:
        """The key as the user wrote it, with its file."""
        return f"{self.path}: {self.prefix}{key}"

    def number(self, key, default=None, allowed: Range | None = None) -> float:
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
                value):
            raise self._bad(key, value, "a number" + (f" in {allowed}" if allowed else ""))
        return allowed.check(self.name(key), value) if allowed else float(value)

    def integer(self, key, default=None, allowed: Range | None = None) -> int:
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self._bad(key, value, "an integer")
        if allowed:
            allowed.check(self.name(key), value)
        return value

    def boolean(self, key, default=None) -> bool:
        value = self.get(key, default)
        if not isinstance(value, bool):
            raise self._bad(key, value, "true or false")
        return value

    def text(self, key, default=None, allowed=None) -> str:
        value = self.get(key, default)
        if not isinstance(value, str) or (allowed and value not in allowed):
            raise self._bad(key, value, f"one of {list(allowed)}" if allowed else "a string")
        return value

    def texts(self, key, default=None) -> tuple[str, ...]:
        """A non-empty list of names, none repeated (compared without case)."""
        value = self.get(key, default)
        if not isinstance(value, list) or not value or not all(
                isinstance(v, (str, int)) and not isinstance(v, bool) for v in value):
            raise self._bad(key, value, "a non-empty list of names")
        names = tuple(str(v).strip() for v in value)
        check_unique(self.name(key), names, same=str.lower)
        return names

    def numbers(self, key, default=None, allowed: Range = Range(),
                unique: bool = True) -> tuple[float, ...]:
        """A non-empty list of numbers in `allowed`, none repeated unless `unique` is off."""
        value = self.get(key, default)
        if not isinstance(value, list) or not value or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            raise self._bad(key, value, "a non-empty list of numbers")
        if unique:
            check_unique(self.name(key), value)
        return check_each(self.name(key), value, allowed)

    def unknown(self, known) -> tuple[str, ...]:
        return tuple(f"{self.prefix}{k}" for k in self.data if k not in known)


def read_task_config(path: str | Path) -> PnnlTask:
    """A PnnlTask from a PNNL load-shedding task JSON (module docstring)."""
    path = Path(path)
    keys = _Keys(_load(path), path)
    for key, allowed in (("observationStateTypes", "voltageMag"), ("actionTypes", "LoadShed")):
        if keys.texts(key, [allowed]) != (allowed,):
            raise keys._bad(key, keys.get(key), f"[{allowed!r}] (the only kind implemented)")
    keys.text("actionSpaceType", "continuous", allowed=("continuous",))
    observation_scope = keys.text("observationScopeType", allowed=("Bus", "Zone"))
    action_scope = keys.text("actionScopeType", allowed=("Bus", "Zone"))
    ranges = keys.get("actionValueRanges")
    if not (isinstance(ranges, list) and ranges and all(
            isinstance(r, list) and len(r) == 2 and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in r)
            for r in ranges)):
        raise keys._bad("actionValueRanges", ranges, "a list of [low, high] pairs")
    if len({tuple(r) for r in ranges}) != 1:
        raise keys._bad("actionValueRanges", ranges, "one range shared by every action bus "
                        "(per-bus ranges are not implemented)")
    low, high = (float(v) for v in ranges[0])
    params = {field: keys.number(key, allowed=PARAM_RANGES[field].negated()
                                 if key == "unstableReward" else PARAM_RANGES[field])
              for key, field in PARAM_KEYS.items()}
    params["unstable_penalty"] = -params["unstable_penalty"]
    params.update(action_low=low, action_high=high)
    written = {field: keys.name(key) for key, field in PARAM_KEYS.items()}
    written.update(action_low=keys.name("actionValueRanges[0][0]"),
                   action_high=keys.name("actionValueRanges[0][1]"))
    check_params(params, written.get)
    notes = [f"{key} = {keys.get(key)!r}: {why}" for key, why in _NOTED_TASK_KEYS.items()
             if key in keys.data]
    p_mw = (keys.numbers("actionBusesPValue", unique=False)
            if "actionBusesPValue" in keys.data else None)
    action = keys.texts("actionScopeAry")
    observed = keys.texts("observationScopeAry")
    if len(ranges) not in (1, len(action)) and action_scope == "Bus":
        raise keys._bad("actionValueRanges", ranges, f"one pair, or one per action bus "
                        f"({len(action)})")
    return PnnlTask(
        source=str(path), name=keys.text("environmentName", path.stem),
        observation_scope=observation_scope, observed=observed,
        observed_min_kv=(keys.number("observationVoltThreshold", 0.0, Range(0, 1e7, "V"))
                         / 1000.0 if observation_scope == "Zone" else 0.0),
        action_scope=action_scope, action=action,
        history=keys.integer("historyObservationSize", 1, HISTORY),
        agent_dt=keys.number("envStepTimeInSec", allowed=AGENT_DT),
        include_action_status=keys.boolean("includeActionStatusInObservations", True),
        params=params, fault_buses=keys.texts("faultBusCandidates"),
        fault_starts=keys.numbers("faultStartTimeCandidates", [1.0], FAULT_TIME),
        fault_durations=keys.numbers("faultDurationCandidates", allowed=FAULT_TIME),
        counts={k: keys.integer(k) for k in COUNT_KEYS if k in keys.data},
        action_p_mw=p_mw, notes=tuple(notes), unknown=keys.unknown(_TASK_KEYS))


def read_sim_config(path: str | Path) -> PnnlSimConfig:
    """A PnnlSimConfig from a PNNL dynamic-simulation JSON (e.g. IEEE39_dyn_config.json)."""
    path = Path(path)
    keys = _Keys(_load(path), path)
    method = keys.text("dynMethod", "MODIFIED_EULER")
    notes = [f"{key} = {keys.get(key)!r}: {why}" for key, why in _NOTED_SIM_KEYS.items()
             if key in keys.data]
    if method != "MODIFIED_EULER":
        notes.append(f"dynMethod = {method!r}: this simulator integrates by modified Euler "
                     "(Heun) whatever the file says")
    fault_r = fault_x = None
    unknown = list(keys.unknown(set(_NOTED_SIM_KEYS) | {"dynMethod", "simuTimeStepSec",
                                                       "totalSimuTimeSec", "acscConfigBean"}))
    acsc = keys.get("acscConfigBean", {}, required=False)
    if acsc:
        if not isinstance(acsc, dict):
            raise keys._bad("acscConfigBean", acsc, "a JSON object")
        bean = _Keys(acsc, path, "acscConfigBean.")
        bean.text("type", "BUS_FAULT", allowed=("BUS_FAULT",))
        bean.text("category", "GROUND_3P", allowed=("GROUND_3P",))
        z = bean.get("zLG", {"re": 0.0, "im": 0.0})
        z_keys = _Keys(z if isinstance(z, dict) else {}, path, "acscConfigBean.zLG.")
        if not isinstance(z, dict):
            raise bean._bad("zLG", z, "an object {re, im}")
        r = z_keys.number("re", 0.0, FAULT_IMPEDANCE)
        x = z_keys.number("im", 0.0, FAULT_IMPEDANCE)
        if r or x:
            fault_r, fault_x = r, x
        else:
            notes.append("acscConfigBean.zLG = 0: a bolted fault, represented by the default "
                         "fault reactance")
        rest = [k for k in acsc if k not in _ACSC_USED]
        if rest:
            notes.append(f"acscConfigBean {', '.join(rest)}: the original's example fault and "
                         "load-flow settings; faults come from the task set")
    return PnnlSimConfig(source=str(path), dt=keys.number("simuTimeStepSec", allowed=DT),
                         t_end=keys.number("totalSimuTimeSec", allowed=EPISODE), fault_r=fault_r,
                         fault_x=fault_x, notes=tuple(notes), unknown=tuple(unknown))
