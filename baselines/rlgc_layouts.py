"""What the PARS study's published networks observe and act on, by RAW bus numbers.

A published network (`baselines.rlgc`) reads, per observation, the voltage magnitudes at its
voltage buses and then the connected load fractions at its action buses, and outputs one
action per action bus. Its layout is stated here by bus numbers, apart from any study: on a
study whose environment observes those buses and acts on those buses, `ObservationLayout.
indices` picks and orders the network's inputs from the study's observation (whatever else
it observes, in whatever order) and places its actions among the study's action buses (the
others shed nothing). The study's observed buses stay what the reward and the recovery check
read, the same for every controller evaluated on it.

The layouts (../shared/reference/rlgc-policies/README.md, "Observation layouts"):
  IEEE39: buses 504, 507, 508, 518, then the fractions at 504, 507, 518 (the task file
    IEEE39_RL_loadShedding_3motor_continuous_reducedActionRange_gp.json; GridPACK's input
    input_39bus_step005_training_v33.xml observes the same buses and loads).
  IEEE300: the 108 zone-1 buses at or above 60 kV of IEEE300Bus_modified_noHVDC_v2.raw, in
    RAW order, then the fractions at the 46 action buses of the task file
    IEEE300_RL_loadShedding_zone1_continuous_LSTM_new_lessfaultbuses_moreActionBuses_
    multipfcases.json, in its actionScopeAry order (Bus<N>_loadBus: the composite load's
    load bus 200000 + N of the study's grid).
"""
from __future__ import annotations

import dataclasses

from jaxgrid.env import EnvConfig


@dataclasses.dataclass(frozen=True)
class ObservationLayout:
    """The inputs and outputs of a published network (one observation; stacked ones repeat
    it, oldest first).

    Attributes:
      name: a short name for messages.  source: where the layout is stated.
      voltage_buses: RAW numbers of the buses whose voltage magnitudes (p.u.) come first.
      action_buses: RAW numbers of the buses it sheds at, in output order; their connected
        load fractions follow the voltages in the input.
      action_low, action_high: the action range (fraction of the initial load per step)
        its output t in [-1, 1] maps onto linearly.
    """

    name: str
    source: str
    voltage_buses: tuple[int, ...]
    action_buses: tuple[int, ...]
    action_low: float = -0.2
    action_high: float = 0.0

    @property
    def frame_size(self) -> int:
        """Inputs per observation."""
        return len(self.voltage_buses) + len(self.action_buses)

    def indices(self, config: EnvConfig, owner: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """(picks, slots): picks (frame_size,) index one observation of an environment with
        `config` (voltages at its observed buses, then fractions at its action buses) in this
        layout's input order; slots (n_action,) place the outputs among its action buses.
        ValueError naming `owner` (the file) and the buses the environment lacks."""
        observed, acting = config.observed_buses, config.action_buses
        lacking = [("observes the voltage at", [b for b in self.voltage_buses
                                               if b not in observed], "observes", observed),
                   ("observes the load fraction at and sheds at", [
                       b for b in self.action_buses if b not in acting], "acts on", acting)]
        for what, missing, does, buses in lacking:
            if missing:
                raise ValueError(f"{owner} ({self.name} layout, {self.source}) {what} buses "
                                 f"{missing}, which this study's environment does not; it "
                                 f"{does} {list(buses)}")
        if not config.include_action_status:
            raise ValueError(f"{owner} reads the load fractions at its action buses: the "
                             "study needs include_action_status = true")
        picks = tuple(observed.index(b) for b in self.voltage_buses) + tuple(
            len(observed) + acting.index(b) for b in self.action_buses)
        return picks, tuple(acting.index(b) for b in self.action_buses)


IEEE39 = ObservationLayout(
    "IEEE39", "IEEE39_RL_loadShedding_3motor_continuous_reducedActionRange_gp.json",
    voltage_buses=(504, 507, 508, 518), action_buses=(504, 507, 518))

IEEE300 = ObservationLayout(
    "IEEE300", "zone-1 buses >= 60 kV of IEEE300Bus_modified_noHVDC_v2.raw and the "
               "actionScopeAry of IEEE300_RL_loadShedding_zone1_continuous_LSTM_new_"
               "lessfaultbuses_moreActionBuses_multipfcases.json",
    voltage_buses=(1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 19, 20, 21, 22,
                   23, 24, 25, 26, 27, 33, 34, 35, 36, 37, 38, 39, 40, 41, 42, 43, 44, 45, 46,
                   47, 48, 49, 51, 52, 53, 54, 55, 57, 58, 59, 60, 61, 62, 63, 64, 69, 70, 71,
                   72, 73, 74, 76, 77, 78, 79, 80, 81, 84, 85, 86, 87, 88, 89, 90, 91, 92, 94,
                   97, 98, 99, 100, 102, 103, 104, 105, 107, 108, 109, 110, 112, 113, 114, 201,
                   207, 319, 320, 322, 323, 324, 526, 528, 531, 552, 562, 609, 1190, 1200),
    action_buses=(200020, 200017, 200005, 200061, 200073, 200059, 200076, 200044, 200014,
                  200038, 200010, 200526, 200015, 200006, 200071, 200319, 200108, 201190,
                  200057, 200009, 200049, 200001, 200041, 200037, 200099, 200011, 200022,
                  200102, 200021, 200077, 200063, 200027, 200053, 200098, 200090, 200110,
                  200052, 200094, 200008, 200013, 200047, 200072, 200002, 200070, 200033,
                  200562))

PUBLISHED = (IEEE39, IEEE300)
