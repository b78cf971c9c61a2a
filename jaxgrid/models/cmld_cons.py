"""CON table of the WECC composite load CMLDBLU2 / CMLDBLU1 (`shared/specs/cmld.md` §2.1).

PSS/E CON order with units, meanings and allowed ranges, read by `jaxgrid.models.cmld` (the
model) and `jaxgrid.models.cmld_init` (its initialisation). Motor D's CONs are those of
ACMTBLU1 (`jaxgrid.models.acmotor`), CompLF called LFmD.
"""
from __future__ import annotations

import dataclasses

from jaxgrid.models.acmotor import Acmtblu1
from jaxgrid.models.base import Con, Sentinel

MOTORS = "abc"  # the three-phase motors A, B, C


def _pu(name, info, lo=-100.0, hi=100.0, positive=False):
    return Con(name, "p.u.", info, lo, hi, positive)


def _frac(name, info):
    return Con(name, "-", info, 0.0, 1.0)


def _motor_block(x: str) -> tuple[Con, ...]:
    """The 20 CONs of motor A, B or C (x = "a", "b", "c"): 10 of the motor, 5 per trip stage."""
    m = x.upper()
    return (
        Con(f"mtyp{x}", "-", f"motor {m} type (3: three-phase)", 0.0, 10.0),
        Con(f"lfm{x}", "-", f"motor {m} loading factor MW/MVA", 0.0, 10.0, positive=True),
        _pu(f"rs{x}", f"motor {m} stator resistance, motor base", 0.0, 10.0),
        _pu(f"ls{x}", f"motor {m} synchronous reactance, motor base", 0.0, 100.0, True),
        _pu(f"lp{x}", f"motor {m} transient reactance, motor base", 0.0, 100.0, True),
        _pu(f"lpp{x}", f"motor {m} subtransient reactance, motor base", 0.0, 100.0, True),
        Con(f"tpo{x}", "s", f"motor {m} transient open-circuit time constant", 0.0, 100.0,
            positive=True),
        Con(f"tppo{x}", "s", f"motor {m} subtransient open-circuit time constant", 0.0, 100.0),
        Con(f"h{x}", "s", f"motor {m} inertia constant, motor base", 0.0, 100.0, positive=True),
        Con(f"etrq{x}", "-", f"motor {m} load-torque speed exponent", -10.0, 10.0),
    ) + _trip_stage(x, "1") + _trip_stage(x, "2")


def _trip_stage(x: str, k: str) -> tuple[Con, ...]:
    """The 5 CONs of UV trip stage k of motor x: Vtr, Ttr, Ftr, Vrc, Trc (spec §5)."""
    m = x.upper()
    never_trips = Sentinel(f"motor {m}'s stage-{k} UV trip never acts")
    never_recloses = Sentinel(f"motor {m}'s stage-{k} trip never recloses")
    return (
        _pu(f"vtr{k}{x}", f"motor {m} UV stage-{k} trip voltage (0: off)", 0.0, 2.0),
        Con(f"ttr{k}{x}", "s", f"motor {m} UV stage-{k} trip time", 0.0, 1e6,
            sentinel=never_trips),
        _frac(f"ftr{k}{x}", f"motor {m} fraction tripped by stage {k}"),
        Con(f"vrc{k}{x}", "p.u.", f"motor {m} stage-{k} reclose voltage", 0.0, 10.0,
            sentinel=never_recloses),
        Con(f"trc{k}{x}", "s", f"motor {m} stage-{k} reclose time", 0.0, 1e6,
            sentinel=never_recloses),
    )


# Motor D: the ACMTBLU1 CONs in ACMTBLU1 order, CompLF called LFmD (spec §2.1 k = 97-131).
MOTOR_D_CONS = tuple(dataclasses.replace(c, name="lfmd") if c.name == "complf" else c
                     for c in Acmtblu1.cons)
# (ACMTBLU1 name, CMLD name) of each motor-D CON
MOTOR_D_NAMES = tuple((c.name, d.name) for c, d in zip(Acmtblu1.cons, MOTOR_D_CONS))

CONS_BLU1 = (
    Con("mva", "MVA", "load MVA base (> 0 MVA; < 0: P/|MVA|; 0: P/0.8)", -1e5, 1e5),
    _pu("bss", "substation shunt susceptance, load base", -100.0, 100.0),
    _pu("rfdr", "feeder resistance, load base", 0.0, 10.0),
    _pu("xfdr", "feeder reactance, load base", 0.0, 10.0),
    _frac("fb", "share of the feeder compensation at the substation end"),
    _pu("xxf", "substation transformer reactance, load base", 0.0, 10.0, positive=True),
    _pu("tfixhs", "high-side fixed tap", 0.0, 2.0, positive=True),
    _pu("tfixls", "low-side fixed tap", 0.0, 2.0, positive=True),
    Con("ltc", "-", "1: tap changer active, 0: fixed (only 0 is supported)", 0.0, 1.0),
    _pu("tmin", "minimum LTC tap", 0.0, 2.0, positive=True),
    _pu("tmax", "maximum LTC tap", 0.0, 2.0, positive=True),
    _pu("step", "LTC tap step (0: continuous)", 0.0, 1.0),
    _pu("vmin", "LTC band lower edge", 0.0, 2.0),
    _pu("vmax", "LTC band upper edge", 0.0, 2.0),
    Con("tdel", "s", "LTC time delay before the first step", 0.0, 1e6),
    Con("ttap", "s", "LTC time between steps", 0.0, 1e6),
    _pu("rcomp", "LTC compensation resistance", -10.0, 10.0),
    _pu("xcomp", "LTC compensation reactance", -10.0, 10.0),
    _frac("fma", "fraction of load-bus P: motor A"),
    _frac("fmb", "fraction of load-bus P: motor B"),
    _frac("fmc", "fraction of load-bus P: motor C"),
    _frac("fmd", "fraction of load-bus P: motor D"),
    _frac("fel", "fraction of load-bus P: electronic load"),
    Con("pfel", "-", "electronic load power factor (< 0: leading)", -1.0, 1.0),
    _pu("vd1", "electronic load starts dropping out below", 0.0, 2.0),
    _pu("vd2", "all electronic load out below", 0.0, 2.0),
    Con("pfs", "-", "static load power factor (< 0: leading)", -1.0, 1.0),
    Con("p1e", "-", "static P exponent 1", -10.0, 10.0),
    Con("p1c", "-", "static P coefficient 1", -10.0, 10.0),
    Con("p2e", "-", "static P exponent 2", -10.0, 10.0),
    Con("p2c", "-", "static P coefficient 2", -10.0, 10.0),
    Con("pfrq", "p.u. P / p.u. f", "static P frequency sensitivity", -100.0, 100.0),
    Con("q1e", "-", "static Q exponent 1", -10.0, 10.0),
    Con("q1c", "-", "static Q coefficient 1", -10.0, 10.0),
    Con("q2e", "-", "static Q exponent 2", -10.0, 10.0),
    Con("q2c", "-", "static Q coefficient 2", -10.0, 10.0),
    Con("qfrq", "p.u. Q / p.u. f", "static Q frequency sensitivity", -100.0, 100.0),
) + _motor_block("a") + _motor_block("b") + _motor_block("c") + MOTOR_D_CONS
CON_FRCEL = _frac("frcel", "fraction of dropped electronic load that recovers")
