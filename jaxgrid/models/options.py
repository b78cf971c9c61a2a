"""Readings of load-model data where the specifications or the reference simulators leave a
choice: `MotorOptions` (ACMTBLU1, induction motors, the composite load's motors) and
`CompositeOptions` (CMLDBLU1/2). Plain settings that `LoadSite` carries to the models' `init`;
this module imports no model.
"""
from __future__ import annotations

import dataclasses

SHARE_MODES = ("gridpack", "psse_load_record", "interpss_bus_total", "fraction:x")
NAMED_SHARES = SHARE_MODES[:3]
HEATING = ("stalled", "gridpack")
CONTACTORS = ("memory", "gridpack")
VX_RULES = ("reference_running1", "spec_running2")
EXTRA_VAR = ("load_end", "none")
SHEDDING = ("end_use", "feeder")
COMPENSATION = ("bf", "static_q")
READINGS = ("wecc", "interpss", "interpss_no_ac")  # CompositeOptions.reading


@dataclasses.dataclass(frozen=True)
class MotorOptions:
    """Readings of motor-load data where the reference simulators disagree
    (`jaxgrid.models.acmotor` docstring).

    Attributes:
      share_mode: "gridpack" | "psse_load_record" | "interpss_bus_total" | "fraction:x"
        (0 < x <= 1).
      vx_rule: "reference_running1" | "spec_running2".
      curve_offsets: "v0" | "1pu".
      restall_b: let a restarted part B stall again (per-part timers).
      heating: "stalled" | "gridpack": which ACMTBLU1 parts heat their windings.
      contactor: "memory" | "gridpack": the ACMTBLU1 contactor's reclose rule.
      stiff_below: s; induction-motor subtransient stages faster than this are dropped
        (2 × a 5 ms step).
    """

    share_mode: str = "gridpack"
    vx_rule: str = "reference_running1"
    curve_offsets: str = "v0"
    restall_b: bool = False
    heating: str = "stalled"
    contactor: str = "memory"
    stiff_below: float = 0.01

    def __post_init__(self):
        if self.share_mode not in NAMED_SHARES:
            x = self.share_fraction
            if x is None or not 0.0 < x <= 1.0:
                raise ValueError(f"share_mode = {self.share_mode!r}: allowed "
                                 f"{', '.join(SHARE_MODES)} with 0 < x <= 1")
        if self.vx_rule not in VX_RULES:
            raise ValueError(f"vx_rule = {self.vx_rule!r}: allowed {', '.join(VX_RULES)}")
        if self.contactor not in CONTACTORS:
            raise ValueError(f"contactor = {self.contactor!r}: allowed {', '.join(CONTACTORS)}")
        if self.heating not in HEATING:
            raise ValueError(f"heating = {self.heating!r}: allowed {', '.join(HEATING)}")
        if self.curve_offsets not in ("v0", "1pu"):
            raise ValueError(f"curve_offsets = {self.curve_offsets!r}: allowed 'v0' or '1pu'")
        if not self.stiff_below >= 0:
            raise ValueError(f"stiff_below = {self.stiff_below!r} s: must be >= 0")

    @property
    def share_fraction(self) -> float | None:
        """x of "fraction:x", else None."""
        head, _, value = self.share_mode.partition(":")
        if head != "fraction":
            return None
        try:
            return float(value)
        except ValueError:
            return None


@dataclasses.dataclass(frozen=True)
class CompositeOptions:
    """Readings of the composite load where the specification leaves a choice
    (`jaxgrid.models.cmld` docstring).

    Attributes:
      compensation: "bf" (default; spec §6 steps 3-5, WECC): the feeder compensation Bf
        closes the reactive balance at the load bus; "static_q" (InterPSS, spec §6 last
        paragraph): Bf = 0 and the static load's Q takes the mismatch.
      extra_var: "load_end" (default): a tripped component takes its initial-MW share of the
        load-end compensation (1 − Fb)·Bf with it; "none": the compensation stays.
      v_floor: p.u.; the initial load-bus voltage is raised to at least this by scaling the
        feeder impedance down (spec §6 step 6; WECC/InterPSS 0.95). 0 switches it off.
      floor_step: fraction of the given feeder impedance removed per adjustment (0.01).
      shedding: "end_use" (default, spec §9): the load slot's connected fraction scales
        every component and the load-end compensation; "feeder": it scales the whole feeder
        (transformer, shunts, feeder and components) as seen from the system bus, which
        then gets a load slot too (`CmldFeederShed`).
      reading: "wecc" (default): the record as the WECC description reads it; "interpss":
        as the InterPSS of the RLGC environments reads it (../shared/reference/
        interpss-cmld.md; `cmld_init.interpss_cons`): LFmD 0.85 (not mapped), motors A-C
        with speed-squared load torque and no UV trips, the electronic and static loads one
        constant-impedance remainder, no feeder compensation Bf (the remainder's Q closes the
        balance, as `compensation="static_q"`, whatever `compensation` says);
        "interpss_no_ac": that, with motors A-C in the remainder too (InterPSS builds from
        June 2020 to May 2021, which include the RLGC 300-bus jars).
    """

    compensation: str = "bf"
    extra_var: str = "load_end"
    v_floor: float = 0.95
    floor_step: float = 0.01
    shedding: str = "end_use"
    reading: str = "wecc"

    def __post_init__(self):
        if self.extra_var not in EXTRA_VAR:
            raise ValueError(f"extra_var = {self.extra_var!r}: allowed {', '.join(EXTRA_VAR)}")
        if self.compensation not in COMPENSATION:
            raise ValueError(f"compensation = {self.compensation!r}: allowed "
                             f"{', '.join(COMPENSATION)}")
        if self.shedding not in SHEDDING:
            raise ValueError(f"shedding = {self.shedding!r}: allowed {', '.join(SHEDDING)}")
        if self.reading not in READINGS:
            raise ValueError(f"reading = {self.reading!r}: allowed {', '.join(READINGS)}")
        if not 0.0 <= self.v_floor < 1.5:
            raise ValueError(f"v_floor = {self.v_floor!r} p.u.: allowed [0, 1.5)")
        if not 0.0 < self.floor_step < 1.0:
            raise ValueError(f"floor_step = {self.floor_step!r}: allowed (0, 1)")
