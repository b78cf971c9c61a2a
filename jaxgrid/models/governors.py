"""Turbine-governors: TGOV1, IEEEG1, WSIEG1, GAST, IEESGO, HYGOV, GGOV1.

CON orders, equations and initialisation follow `shared/specs/machines-exciters-governors.md`
§9-§13 (PSS/E model library conventions); GGOV1, which the spec does not cover, is described
in its class. Every quantity is per unit on the machine base MBASE (GGOV1: on its turbine
rating, converted at its ports); the inputs are the machine's speed deviation Δω (p.u.,
positive = overspeed) and electrical power, the output its mechanical power Pm (p.u. MBASE);
time constants in seconds.

Zero time constants bypass a lag (output = input, state held) where the structure allows;
where a division remains the CON must be > 0 and such data are rejected when read.
Non-windup limits freeze the derivative inside `rates` and are listed in `limits`, so
that the integrator can clip the state after every update (spec §0).
"""
from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from jaxgrid.records import DyrRecord
from jaxgrid.models.base import (LIMIT_TOL, Array, Con, DeviceModel, Initial, ModelError,
                                 Params, Signals, StartPoint, States, device_label,
                                 freeze_at_limits, lag, lead_lag_output, outside_limits, safe)

# Smallest gate opening used in the HYGOV head h = (q/g)², p.u.: a closed gate with
# flow is unphysical; the floor keeps h finite (and differentiable) if the gate closes.
G_OPEN_MIN = 1e-3

# |ΣK − 1| above which IEEEG1 power fractions are reported as not summing to one.
K_SUM_TOL = 1e-6

# WSIEG1: the limits an initial valve position may violate, with the side it lies beyond
# (+1 above a maximum, -1 below a minimum), and the margin GridPACK moves them past it, p.u.
WIDENED = (("pmax", 1), ("pmin", -1), ("uo", 1), ("uc", -1))
WIDEN_MARGIN = 0.1

# GGOV1's acceleration limiter is written with the simulation step DELT (PSS/E): fsra =
# previous fsr + Ka·DELT·(Aset − acceleration). Here the previous fsr is a lag of this time
# constant (OPAL-RT's default), s; Heun keeps that lag stable up to 20-ms steps.
GGOV1_DELT = 0.01


def _t(name: str, info: str, positive: bool = False) -> Con:
    return Con(name, "s", info, 0.0, positive=positive)


def _pu(name: str, info: str, lo: float = -np.inf, positive: bool = False) -> Con:
    return Con(name, "p.u.", info, lo, positive=positive)


def _fraction(name: str, info: str) -> Con:
    return Con(name, "p.u.", info, 0.0, 1.0)


def _lag_output(x: Array, u: Array, t: Array) -> Array:
    """Output of a unity lag whose state is x: x, or its input u where t == 0 (bypassed)."""
    return jnp.where(t > 0, x, u)


class GovernorPorts(NamedTuple):
    """What a governor reads from its machine, arrays (n_gov,).

    Attributes:
      dw: speed deviation Δω, p.u.
      pe: electrical power at the terminals, p.u. MBASE.
    """

    dw: Array
    pe: Array


class GovernorStart(NamedTuple):
    """What a governor starts from, arrays (n,): pm, the mechanical power p.u. MBASE it
    holds at rest; pe, the electrical power p.u. MBASE; mbase, its machine's MBASE, MVA."""

    pm: Array
    pe: Array
    mbase: Array


class GovernorModel(DeviceModel):
    """A turbine-governor family: Pm (p.u. MBASE) from the speed deviation Δω (p.u.).

    `p` and states are dicts of arrays (n_gov,), one row per unit. Its rates drive the
    machine's mechanical power Pm.
    """

    output = "pm"

    @classmethod
    def ports(cls, signals: Signals, k: Array, flags: States) -> GovernorPorts:
        return GovernorPorts(dw=signals.dw[k], pe=signals.pe[k])

    @classmethod
    def init_ports(cls, point: StartPoint, k: Array, labels) -> GovernorStart:
        return GovernorStart(pm=point.signals.pm[k], pe=point.signals.pe[k],
                             mbase=jnp.asarray(point.mbase[k]))

    @classmethod
    def init(cls, p: Params, start: GovernorStart) -> Initial:
        """Params with the reference added and states for a steady state at start.pm (no
        output)."""
        raise NotImplementedError

    @classmethod
    def rates(cls, p: Params, x: States, ports: GovernorPorts) -> tuple[Array, States]:
        """(Pm (n,) p.u. MBASE, {state: d/dt}) at speed deviation ports.dw (n,) p.u."""
        raise NotImplementedError


class _ValveLimited(GovernorModel):
    """A governor whose first state x1 is a valve held non-windup in [VMIN, VMAX]."""

    @classmethod
    def check_combination(cls, p):
        if p["vmin"] > p["vmax"]:
            return f"needs VMIN <= VMAX (VMIN = {p['vmin']:g}, VMAX = {p['vmax']:g})"
        return None

    @classmethod
    def limits(cls, p):
        return {"x1": (p["vmin"], p["vmax"])}


class Tgov1(_ValveLimited):
    """Steam turbine-governor TGOV1 (spec §9): droop, non-windup valve lag, reheat lead-lag."""

    name = "TGOV1"
    cons = (_pu("r", "permanent droop R", 0.0, positive=True),
            _t("t1", "valve time constant T1", positive=True),
            _pu("vmax", "maximum valve position VMAX"),
            _pu("vmin", "minimum valve position VMIN"),
            _t("t2", "turbine lead time constant T2 (numerator)"),
            _t("t3", "turbine lag time constant T3 (reheater)", positive=True),
            _pu("dt", "turbine damping coefficient Dt", 0.0))
    states = ("x1", "x2")

    @classmethod
    def init(cls, p, start):
        pm0 = jnp.asarray(start.pm, dtype=float)
        return Initial(dict(p, pref=p["r"] * pm0), {"x1": pm0, "x2": pm0}, {})

    @classmethod
    def rates(cls, p, x, ports):
        dw = ports.dw
        dx1 = ((p["pref"] - dw) / p["r"] - x["x1"]) / p["t1"]
        dx = {"x1": freeze_at_limits(dx1, x["x1"], p["vmin"], p["vmax"]),
              "x2": (x["x1"] - x["x2"]) / p["t3"]}
        return lead_lag_output(x["x2"], x["x1"], p["t2"], p["t3"]) - p["dt"] * dw, dx


class Ieeeg1(GovernorModel):
    """IEEE type 1 steam governor IEEEG1 (spec §10), one machine (JBUS = 0).

    The low-pressure outputs K2, K4, K6, K8 would drive a second machine and are unused.
    """

    name = "IEEEG1"
    n_icons = 2
    cons = (_pu("k", "governor gain K (1/droop)", 0.0),
            _t("t1", "governor lag time constant T1"),
            _t("t2", "governor lead time constant T2"),
            _t("t3", "valve positioner time constant T3", positive=True),
            Con("uo", "p.u./s", "maximum valve opening rate Uo", 0.0, positive=True),
            Con("uc", "p.u./s", "maximum valve closing rate Uc (< 0)", hi=0.0),
            _pu("pmax", "maximum valve opening PMAX"),
            _pu("pmin", "minimum valve opening PMIN"),
            _t("t4", "steam chest time constant T4"),
            _fraction("k1", "HP fraction after T4"), _fraction("k2", "LP fraction after T4"),
            _t("t5", "second boiler pass / reheater time constant T5"),
            _fraction("k3", "HP fraction after T5"), _fraction("k4", "LP fraction after T5"),
            _t("t6", "third boiler pass time constant T6"),
            _fraction("k5", "HP fraction after T6"), _fraction("k6", "LP fraction after T6"),
            _t("t7", "fourth boiler pass time constant T7"),
            _fraction("k7", "HP fraction after T7"), _fraction("k8", "LP fraction after T7"))
    states = ("x_ll", "pgv", "y4", "y5", "y6", "y7")

    @classmethod
    def check_icons(cls, record: DyrRecord, icons) -> None:
        jbus, machine = icons
        if jbus != 0:
            raise ModelError(f"{device_label(record)}: ICON JBUS = {jbus:g} (M = {machine:g}): "
                             f"a second (low-pressure) machine is not supported; use JBUS = 0")

    @classmethod
    def check_combination(cls, p):
        if p["uc"] >= 0:
            return f"needs Uc < 0 (Uc = {p['uc']:g} p.u./s): the valve could never close"
        if p["pmin"] > p["pmax"]:
            return f"needs PMIN <= PMAX (PMIN = {p['pmin']:g}, PMAX = {p['pmax']:g})"
        if p["k1"] + p["k3"] + p["k5"] + p["k7"] <= 0:
            return "needs K1 + K3 + K5 + K7 > 0 (no power reaches the machine)"
        return None

    @classmethod
    def prepare(cls, p):
        return dict(p, k_hp=p["k1"] + p["k3"] + p["k5"] + p["k7"])

    @classmethod
    def notes(cls, p, labels=()):
        out = []
        k_hp = p["k1"] + p["k3"] + p["k5"] + p["k7"]
        k_lp = p["k2"] + p["k4"] + p["k6"] + p["k8"]
        for k, (hp, lp) in enumerate(zip(k_hp, k_lp)):
            label = labels[k] if labels else f"IEEEG1 unit {k}"
            if abs(hp + lp - 1.0) > K_SUM_TOL:
                out.append(f"{label}: K1 + ... + K8 = {hp + lp:g}, not 1")
            if lp > 0:
                out.append(f"{label}: K2 + K4 + K6 + K8 = {lp:g} drive no machine "
                           f"(JBUS = 0) and are dropped")
        return out

    @classmethod
    def init(cls, p, start):
        pgv0 = jnp.asarray(start.pm, dtype=float) / p["k_hp"]
        x = {"x_ll": jnp.zeros_like(pgv0), "pgv": pgv0,
             "y4": pgv0, "y5": pgv0, "y6": pgv0, "y7": pgv0}
        return Initial(dict(p, p0=pgv0), x, {})

    @classmethod
    def rates(cls, p, x, ports):
        dw = ports.dw
        speed = p["k"] * lead_lag_output(x["x_ll"], dw, p["t2"], p["t1"])
        valve_speed = jnp.clip((p["p0"] - speed - x["pgv"]) / p["t3"], p["uc"], p["uo"])
        dx = {"x_ll": lag(x["x_ll"], dw, p["t1"]),
              "pgv": freeze_at_limits(valve_speed, x["pgv"], p["pmin"], p["pmax"])}
        u, pm = x["pgv"], 0.0
        for stage, t, gain in (("y4", "t4", "k1"), ("y5", "t5", "k3"),
                               ("y6", "t6", "k5"), ("y7", "t7", "k7")):
            dx[stage] = lag(x[stage], u, p[t])
            u = _lag_output(x[stage], u, p[t])
            pm = pm + p[gain] * u
        return pm, dx

    @classmethod
    def limits(cls, p):
        return {"pgv": (p["pmin"], p["pmax"])}


class Wsieg1(Ieeeg1):
    """WECC/Siemens steam governor WSIEG1: IEEEG1 (spec §10) with deadbands, a valve-gain
    table and IBLOCK, one machine (JBUS = 0).

    The two deadbands (DB1 with hysteresis ERR on the speed, DB2 on the valve) and the
    nonlinear valve gain (GV1-PGV5) are not modelled: a record that uses them is rejected
    (GridPACK, the only open implementation, does not apply them either). IBLOCK 1-3 sets
    PMIN and/or PMAX to the initial valve position where they are 0 (the PSS/E rule).

    A valve position that starts outside [PMIN, PMAX] moves that limit to the initial
    position plus a 0.1 p.u. margin, and a valve rate limit it exceeds likewise, as
    GridPACK's WSIEG1 does at initialisation ("limits modified for the initial state"); the
    compile report lists each such change.
    """

    name = "WSIEG1"
    cons = Ieeeg1.cons + (
        _pu("db1", "intentional speed deadband DB1 (not modelled: 0)"),
        _pu("err", "DB1 hysteresis ERR (not modelled: 0)"),
        _pu("db2", "unintentional valve deadband DB2 (not modelled: 0)"),
        *(_pu(f"{axis}{k}", f"valve gain table {axis.upper()}{k} (not modelled: 0)")
          for k in range(1, 6) for axis in ("gv", "pgv")),
        Con("iblock", "-", "IBLOCK: 1 PMIN, 2 PMAX, 3 both := initial valve where 0",
            0.0, 3.0))

    @classmethod
    def check_combination(cls, p):
        unmodelled = [n.upper() for n in ("db1", "err", "db2") + tuple(
            f"{axis}{k}" for k in range(1, 6) for axis in ("gv", "pgv")) if p[n] != 0]
        if unmodelled:
            return (f"{', '.join(unmodelled)} != 0: WSIEG1 deadbands and valve-gain table "
                    "are not modelled (set them to 0)")
        if p["iblock"] != round(p["iblock"]):
            return f"IBLOCK = {p['iblock']:g}: allowed 0, 1, 2, 3"
        return super().check_combination(p)

    @classmethod
    def init(cls, p, start):
        initial = super().init(p, start)
        p, pgv0 = dict(initial.params), np.asarray(initial.states["pgv"])
        block = np.asarray(p["iblock"])
        p["pmin"] = np.where(((block == 1) | (block == 3)) & (p["pmin"] == 0), pgv0, p["pmin"])
        p["pmax"] = np.where(((block == 2) | (block == 3)) & (p["pmax"] == 0), pgv0, p["pmax"])
        p["data_limits"] = np.stack([np.asarray(p[name]) for name, _ in WIDENED])
        for name, sign in WIDENED:
            outside = sign * (pgv0 - p[name]) > 0
            p[name] = np.where(outside, pgv0 + sign * WIDEN_MARGIN, p[name])
        return initial._replace(params=p)

    @classmethod
    def notes(cls, p, labels=()):
        out = super().notes(p, labels)
        if "data_limits" not in p:  # CONs as read, before init
            return out
        for (name, _), before in zip(WIDENED, np.asarray(p["data_limits"])):
            after = np.asarray(p[name])
            for k in np.flatnonzero(after != before):
                label = labels[k] if labels else f"WSIEG1 unit {k}"
                out.append(f"{label}: initial valve {float(np.asarray(p['p0'])[k]):.4g} is outside "
                           f"{name.upper()} = {before[k]:g}: {name.upper()} set to {after[k]:.4g} "
                           f"(GridPACK's rule, margin {WIDEN_MARGIN:g})")
        return out


class Gast(_ValveLimited):
    """Gas turbine GAST (spec §11): droop, load (exhaust temperature) limit, two lags."""

    name = "GAST"
    cons = (_pu("r", "speed droop R", 0.0, positive=True),
            _t("t1", "fuel valve time constant T1", positive=True),
            _t("t2", "fuel system time constant T2", positive=True),
            _t("t3", "load limit (exhaust temperature) time constant T3", positive=True),
            _pu("at", "ambient temperature load limit AT"),
            _pu("kt", "temperature limiter gain KT", 0.0),
            _pu("vmax", "maximum fuel valve opening VMAX"),
            _pu("vmin", "minimum fuel valve opening VMIN"),
            _pu("dturb", "turbine damping coefficient Dturb", 0.0))
    states = ("x1", "x2", "x3")

    @classmethod
    def init(cls, p, start):
        pm0 = jnp.asarray(start.pm, dtype=float)
        return Initial(dict(p, lref=pm0), {"x1": pm0, "x2": pm0, "x3": pm0}, {})

    @classmethod
    def rates(cls, p, x, ports):
        dw = ports.dw
        demand = p["lref"] - dw / p["r"]
        load_limit = p["at"] + p["kt"] * (p["at"] - x["x3"])
        dx1 = (jnp.minimum(demand, load_limit) - x["x1"]) / p["t1"]
        dx = {"x1": freeze_at_limits(dx1, x["x1"], p["vmin"], p["vmax"]),
              "x2": (x["x1"] - x["x2"]) / p["t2"],
              "x3": (x["x2"] - x["x3"]) / p["t3"]}
        return x["x2"] - p["dturb"] * dw, dx

    @classmethod
    def init_violations(cls, p, x):
        """Also x3 (= Pm0) above AT: the load limit would then pull the unit down."""
        return super().init_violations(p, x) | {"x3": x["x3"] > p["at"]}


class Ieesgo(GovernorModel):
    """IEEE standard governor IEESGO (spec §12).

    The speed filter K1·(1 + sT2)/((1 + sT1)(1 + sT3)) is a lead-lag over `t_ll` followed
    by a lag `t_lag`: the lead T2 is paired with T1, or with T3 where T1 = 0, so that it is
    kept whenever one lag exists (with T1 = T3 = 0 the pure lead cannot be realised and
    T2 is ignored).
    """

    name = "IEESGO"
    cons = (_t("t1", "controller lag time constant T1"),
            _t("t2", "controller lead time constant T2"),
            _t("t3", "governor lag time constant T3"),
            _t("t4", "steam chest (delay) time constant T4"),
            _t("t5", "reheater time constant T5"),
            _t("t6", "crossover time constant T6"),
            _pu("k1", "governor gain K1 (1/droop)", 0.0),
            _fraction("k2", "fraction K2 passed to the reheater stage"),
            _fraction("k3", "fraction K3 passed to the crossover stage"),
            _pu("pmax", "maximum valve position PMAX"),
            _pu("pmin", "minimum valve position PMIN"))
    states = ("x_ll", "x_lag", "y4", "y5", "y6")

    @classmethod
    def check_combination(cls, p):
        if p["pmin"] > p["pmax"]:
            return f"needs PMIN <= PMAX (PMIN = {p['pmin']:g}, PMAX = {p['pmax']:g})"
        return None

    @classmethod
    def prepare(cls, p):
        t1_used = p["t1"] > 0
        return dict(p, t_ll=np.where(t1_used, p["t1"], p["t3"]),
                    t_lag=np.where(t1_used, p["t3"], 0.0))

    @classmethod
    def init(cls, p, start):
        pm0 = jnp.asarray(start.pm, dtype=float)
        zero = jnp.zeros_like(pm0)
        x = {"x_ll": zero, "x_lag": zero, "y4": pm0, "y5": p["k2"] * pm0,
             "y6": p["k3"] * p["k2"] * pm0}
        return Initial(dict(p, p0=pm0), x, {})

    @classmethod
    def rates(cls, p, x, ports):
        dw = ports.dw
        lead = lead_lag_output(x["x_ll"], dw, p["t2"], p["t_ll"])
        speed = p["k1"] * _lag_output(x["x_lag"], lead, p["t_lag"])
        pgv = jnp.clip(p["p0"] - speed, p["pmin"], p["pmax"])
        y4 = _lag_output(x["y4"], pgv, p["t4"])
        y5 = _lag_output(x["y5"], p["k2"] * y4, p["t5"])
        y6 = _lag_output(x["y6"], p["k3"] * y5, p["t6"])
        dx = {"x_ll": lag(x["x_ll"], dw, p["t_ll"]),
              "x_lag": lag(x["x_lag"], lead, p["t_lag"]),
              "y4": lag(x["y4"], pgv, p["t4"]),
              "y5": lag(x["y5"], p["k2"] * y4, p["t5"]),
              "y6": lag(x["y6"], p["k3"] * y5, p["t6"])}
        return (1.0 - p["k2"]) * y4 + (1.0 - p["k3"]) * y5 + y6, dx

    @classmethod
    def init_violations(cls, p, x):
        """Valve position Pgv0 = P0 outside the hard clip [PMIN, PMAX]."""
        return {"pgv": outside_limits(p["p0"], p["pmin"], p["pmax"])}


class Hygov(GovernorModel):
    """Hydro turbine-governor HYGOV (spec §13).

    PSS/E names R (permanent droop) and r (temporary droop) coincide in lower case: they
    are `r` and `r_temp` here. VELM placement [verify in spec]: the PI controller
    (1 + sTr)/(r·Tr·s) is a proportional path x1/r plus an integrator xi whose rate
    x1/(r·Tr) is clipped to ±VELM and whose value is non-windup in [GMIN, GMAX]; the
    desired gate c = xi + x1/r itself is not clipped. In the head h = (q/g)² the gate is
    floored at `G_OPEN_MIN`.
    """

    name = "HYGOV"
    cons = (_pu("r", "permanent droop R", 0.0),
            _pu("r_temp", "temporary droop r (PSS/E 'r')", 0.0, positive=True),
            _t("tr", "governor reset time constant Tr", positive=True),
            _t("tf", "filter time constant Tf", positive=True),
            _t("tg", "gate servo time constant Tg", positive=True),
            Con("velm", "p.u./s", "gate velocity limit VELM", 0.0, positive=True),
            _pu("gmax", "maximum gate opening GMAX", 0.0, positive=True),
            _pu("gmin", "minimum gate opening GMIN", 0.0),
            _t("tw", "water inertia time constant TW", positive=True),
            _pu("at", "turbine gain At", 0.0, positive=True),
            _pu("dturb", "turbine damping coefficient Dturb", 0.0),
            _pu("qnl", "no-load flow qNL", 0.0))
    states = ("x1", "xi", "g", "q")

    @classmethod
    def check_combination(cls, p):
        if p["gmin"] >= p["gmax"]:
            return f"needs GMIN < GMAX (GMIN = {p['gmin']:g}, GMAX = {p['gmax']:g})"
        return None

    @classmethod
    def init(cls, p, start):
        q0 = jnp.asarray(start.pm, dtype=float) / p["at"] + p["qnl"]
        x = {"x1": jnp.zeros_like(q0), "xi": q0, "g": q0, "q": q0}
        return Initial(dict(p, nref=p["r"] * q0), x, {})

    @classmethod
    def rates(cls, p, x, ports):
        dw = ports.dw
        c = x["xi"] + x["x1"] / p["r_temp"]
        e = p["nref"] - dw - p["r"] * c
        rate = jnp.clip(x["x1"] / (p["r_temp"] * p["tr"]), -p["velm"], p["velm"])
        head = (x["q"] / jnp.maximum(x["g"], G_OPEN_MIN)) ** 2
        dx = {"x1": (e - x["x1"]) / p["tf"],
              "xi": freeze_at_limits(rate, x["xi"], p["gmin"], p["gmax"]),
              "g": (c - x["g"]) / p["tg"],
              "q": (1.0 - head) / p["tw"]}
        return p["at"] * head * (x["q"] - p["qnl"]) - p["dturb"] * dw * x["g"], dx

    @classmethod
    def limits(cls, p):
        return {"xi": (p["gmin"], p["gmax"])}

    @classmethod
    def init_violations(cls, p, x):
        """Gate g0 = xi0 = q0 outside [GMIN, GMAX]."""
        return {"g": outside_limits(x["g"], p["gmin"], p["gmax"])}


class Ggov1(GovernorModel):
    """GE general governor-turbine GGOV1 as PSS/E has it (ICONs Rselect, Flag; CONs R,
    Tpelec, maxerr, minerr, Kpgov, Kigov, Kdgov, Tdgov, Vmax, Vmin, Tact, Kturb, Wfnl, Tb,
    Tc, Teng, Tfload, Kpload, Kiload, Ldref, Dm, Ropen, Rclose, Kimw, Aset, Ka, Ta, Trate,
    db, Tsa, Tsb, Rup, Rdown: the order of PowerSystems.jl's, ANDES's and GridPACK's readers;
    ANDES implements no GGOV1), the block diagram of IEEE PES-TR1 (2013) §4.2 as OPAL-RT's
    PSS/E library realises it.

    Quantities are per unit of the turbine rating Trate (MW; 0: MBASE): Pelec and Pmech are
    converted by MBASE/Trate at the ports. Speed control: err = clip(deadband(Pref + Pmw −
    Δω − R·Pelec_meas), minerr, maxerr) with Pelec_meas = Pelec/(1 + sTpelec) (Rselect 1;
    Rselect 0: no droop feedback) and the supervisory load control Pmw = Kimw/s of
    (Pmwset − Pelec_meas), non-windup within ±1.1·R; the PID fsrn = Kpgov·err +
    Kdgov·s/(1 + sTdgov)·err + xi, whose integral tracks the low-value-select output fsr,
    dxi/dt = Kigov/Kpgov·(fsr − xi) (GGOV1's anti-windup). Load limit: the fuel flow
    wf = xact·(1 + Δω) (Flag 1) or xact (Flag 0), times (1 + Δω)^Dm where Dm < 0, through
    (1 + sTsa)/(1 + sTsb) and 1/(1 + sTfload) gives the temperature; fsrt = min(xld +
    Kpload·(Ldref/Kturb + Wfnl − temperature), 1) with dxld/dt = Kiload/Kpload·(fsr − xld).
    Acceleration limit: fsra = m + Ka·DELT·(Aset − a) with a = s/(1 + sTa) of Δω and m the
    previous fsr, here dm/dt = (fsr − m)/DELT (DELT = `GGOV1_DELT`). fsr = clip(min(fsrn,
    fsrt, fsra), Vmin, Vmax) (fsra only where Ka > 0); the actuator dxact/dt =
    clip((fsr − xact)/Tact, Rclose, Ropen); Pmech = (1 + sTc)/(1 + sTb) of Kturb·(wf − Wfnl),
    less Dm·Δω where Dm > 0.

    A unit the power flow loads beyond Kturb·(Vmax − Wfnl) gets the Kturb that puts its
    initial stroke at Vmax, and one whose initial stroke lies below Vmin gets that stroke as
    its Vmin, as GridPACK's GGOV1 does (the latter its option for initial limit
    violations); each change is noted. Refused (ModelError naming the
    record): Rselect −1 and −2 (the references disagree on
    which of the valve stroke and the governor output each means), Teng != 0 (a transport
    delay), Kpgov = 0 or Kpload = 0 (their integrals change form), Kdgov != 0 with
    Tdgov = 0, Ka > 0 with Ta = 0 and the pure leads Tc != 0 with Tb = 0, Tsa != 0 with
    Tsb = 0. Rup and Rdown limit the rate of change of the load reference Ldref, which is
    constant here; they are read and have no effect. States: p_meas, x_mw, x_d, x_i, x_act,
    x_turb, x_temp, x_load, x_ld, x_acc, x_fsr, p.u. of Trate.
    """

    name = "GGOV1"
    n_icons = 2
    stored_icons = ("rselect", "flag")
    cons = (_pu("r", "permanent droop R", 0.0),
            _t("tpelec", "electrical power transducer time constant (0: bypassed)"),
            _pu("maxerr", "speed error upper limit"),
            _pu("minerr", "speed error lower limit"),
            _pu("kpgov", "governor proportional gain", 0.0, positive=True),
            _pu("kigov", "governor integral gain (1/s)", 0.0),
            _pu("kdgov", "governor derivative gain (s)", 0.0),
            _t("tdgov", "governor derivative time constant"),
            _pu("vmax", "fuel stroke upper limit"), _pu("vmin", "fuel stroke lower limit"),
            _t("tact", "actuator time constant", positive=True),
            _pu("kturb", "turbine gain", 0.0, positive=True),
            _pu("wfnl", "no-load fuel flow", 0.0),
            _t("tb", "turbine lag time constant (0: bypassed)"),
            _t("tc", "turbine lead time constant"),
            _t("teng", "transport delay of a diesel engine (only 0 is modelled)"),
            _t("tfload", "load limiter time constant (0: bypassed)"),
            _pu("kpload", "load limiter proportional gain", 0.0, positive=True),
            _pu("kiload", "load limiter integral gain (1/s)", 0.0),
            _pu("ldref", "load limiter reference"),
            _pu("dm", "speed sensitivity: damping (> 0) or fuel-flow exponent (< 0)"),
            Con("ropen", "p.u./s", "actuator opening rate limit", 0.0),
            Con("rclose", "p.u./s", "actuator closing rate limit (<= 0)", hi=0.0),
            Con("kimw", "1/s", "supervisory load controller gain", 0.0),
            Con("aset", "p.u./s", "acceleration limiter setpoint"),
            _pu("ka", "acceleration limiter gain (0: no acceleration limiter)", 0.0),
            _t("ta", "acceleration limiter time constant"),
            Con("trate", "MW", "turbine rating (0: MBASE)", 0.0),
            _pu("db", "speed error deadband", 0.0),
            _t("tsa", "temperature detection lead time constant"),
            _t("tsb", "temperature detection lag time constant (0: bypassed)"),
            Con("rup", "p.u./s", "load reference rate-of-increase limit (no effect here)"),
            Con("rdown", "p.u./s", "load reference rate-of-decrease limit (no effect here)"))
    states = ("p_meas", "x_mw", "x_d", "x_i", "x_act", "x_turb", "x_temp", "x_load", "x_ld",
              "x_acc", "x_fsr")

    @classmethod
    def check_icons(cls, record, icons):
        rselect, flag = icons
        if rselect not in (0, 1):
            raise ModelError(f"{device_label(record)}: ICON Rselect = {rselect:g}: supported 1 "
                             "(electrical power) and 0 (no droop feedback); -1 and -2 are not "
                             "modelled (the references disagree on which of the governor "
                             "output and the valve stroke each selects)")
        if flag not in (0, 1):
            raise ModelError(f"{device_label(record)}: ICON Flag = {flag:g}: allowed 0 (fuel "
                             "flow independent of speed), 1 (proportional to speed)")

    @classmethod
    def check_combination(cls, p):
        if p["teng"] != 0:
            return f"TENG = {p['teng']:g} s: the transport delay is not modelled (needs 0)"
        for lead, lag_, gain in (("tc", "tb", None), ("tsa", "tsb", None),
                                 (None, "tdgov", "kdgov"), (None, "ta", "ka")):
            used = p[lead] if lead else p[gain]
            if p[lag_] == 0 and used != 0:
                name = (lead or gain).upper()
                return (f"{lag_.upper()} = 0 with {name} = {used:g}: needs {lag_.upper()} > 0 "
                        f"or {name} = 0")
        for lo, hi in (("minerr", "maxerr"), ("vmin", "vmax")):
            if p[lo] > p[hi]:
                return f"needs {lo.upper()} <= {hi.upper()} ({p[lo]:g} > {p[hi]:g})"
        return None

    @classmethod
    def signals(cls, p: Params, x: States, dw: Array) -> tuple[Array, Array]:
        """(wf, the fuel flow; the temperature detector's input), p.u. of Trate."""
        wf = x["x_act"] * jnp.where(p["flag"] == 1, 1.0 + dw, 1.0)
        speed = jnp.maximum(1.0 + dw, 1e-3)  # (1 + Δω)^Dm, Dm < 0, kept finite
        return wf, wf * jnp.where(p["dm"] < 0, speed ** jnp.minimum(p["dm"], 0.0), 1.0)

    @classmethod
    def init(cls, p, start):
        ratio = jnp.where(p["trate"] > 0, start.mbase / safe(p["trate"]), 1.0)
        pmech0, pelec0 = start.pm * ratio, start.pe * ratio
        # GridPACK's rule: a unit loaded beyond Kturb·(Vmax − Wfnl) gets the Kturb that
        # puts its initial stroke at Vmax
        over = (pmech0 / p["kturb"] + p["wfnl"] > p["vmax"]) & (p["vmax"] > p["wfnl"])
        p = dict(p, kturb_data=p["kturb"], kturb=jnp.where(
            over, pmech0 / jnp.where(over, p["vmax"] - p["wfnl"], 1.0), p["kturb"]))
        fsr0 = pmech0 / p["kturb"] + p["wfnl"]
        p |= {"vmin_data": p["vmin"], "vmin": jnp.minimum(p["vmin"], fsr0)}  # GridPACK's option
        zero = jnp.zeros_like(fsr0)
        x = {"p_meas": pelec0, "x_mw": zero, "x_d": zero, "x_i": fsr0, "x_act": fsr0,
             "x_turb": pmech0, "x_temp": fsr0, "x_load": fsr0, "x_ld": fsr0, "x_acc": zero,
             "x_fsr": fsr0}
        pref = jnp.where(p["rselect"] == 1, p["r"] * pelec0, 0.0)
        return Initial(dict(p, ratio=ratio, pref=pref, pmwset=pelec0), x, {})

    @classmethod
    def rates(cls, p, x, ports):
        dw = ports.dw
        pelec = ports.pe * p["ratio"]
        p_meas = jnp.where(p["tpelec"] > 0, x["p_meas"], pelec)
        e = (p["pref"] + x["x_mw"] - dw
             - jnp.where(p["rselect"] == 1, p["r"] * p_meas, 0.0))
        err = jnp.clip(jnp.sign(e) * jnp.maximum(jnp.abs(e) - p["db"], 0.0),
                       p["minerr"], p["maxerr"])
        fsrn = (p["kpgov"] * err + p["kdgov"] / safe(p["tdgov"]) * (err - x["x_d"])
                + x["x_i"])
        wf, heat = cls.signals(p, x, dw)
        temp = lead_lag_output(x["x_temp"], heat, p["tsa"], p["tsb"])
        load = _lag_output(x["x_load"], temp, p["tfload"])
        fsrt = jnp.minimum(x["x_ld"] + p["kpload"] * (p["ldref"] / p["kturb"] + p["wfnl"]
                                                      - load), 1.0)
        accel = (dw - x["x_acc"]) / safe(p["ta"])
        fsra = jnp.where(p["ka"] > 0, x["x_fsr"] + p["ka"] * GGOV1_DELT * (p["aset"] - accel),
                         jnp.inf)
        fsr = jnp.clip(jnp.minimum(jnp.minimum(fsrn, fsrt), fsra), p["vmin"], p["vmax"])
        tin = p["kturb"] * (wf - p["wfnl"])
        pmech = (lead_lag_output(x["x_turb"], tin, p["tc"], p["tb"])
                 - jnp.where(p["dm"] > 0, p["dm"] * dw, 0.0))
        bound = 1.1 * p["r"]
        dx = {"p_meas": lag(x["p_meas"], pelec, p["tpelec"]),
              "x_mw": freeze_at_limits(p["kimw"] * (p["pmwset"] - p_meas), x["x_mw"],
                                       -bound, bound),
              "x_d": lag(x["x_d"], err, p["tdgov"]),
              "x_i": p["kigov"] / p["kpgov"] * (fsr - x["x_i"]),
              "x_act": jnp.clip((fsr - x["x_act"]) / p["tact"], p["rclose"], p["ropen"]),
              "x_turb": lag(x["x_turb"], tin, p["tb"]),
              "x_temp": lag(x["x_temp"], heat, p["tsb"]),
              "x_load": lag(x["x_load"], temp, p["tfload"]),
              "x_ld": p["kiload"] / p["kpload"] * (fsr - x["x_ld"]),
              "x_acc": lag(x["x_acc"], dw, p["ta"]),
              "x_fsr": (fsr - x["x_fsr"]) / GGOV1_DELT}
        return pmech / p["ratio"], dx

    @classmethod
    def limits(cls, p):
        return {"x_mw": (-1.1 * p["r"], 1.1 * p["r"])}

    @classmethod
    def notes(cls, p, labels=()):
        if "kturb_data" not in p:  # CONs as read, before init
            return []
        out = []
        for name, why in (("kturb", "loaded beyond Kturb·(Vmax − Wfnl) at the power flow: "
                                    "its initial stroke put at Vmax"),
                          ("vmin", "the initial stroke lies below VMIN")):
            changed = np.flatnonzero(np.asarray(p[name]) != np.asarray(p[f"{name}_data"]))
            out += [f"{labels[k] if labels else f'GGOV1 unit {k}'}: {why}: {name.upper()} = "
                    f"{float(p[f'{name}_data'][k]):g} set to {float(p[name][k]):.5g} "
                    "(GridPACK's rule)" for k in changed]
        return out

    @classmethod
    def init_violations(cls, p, x):
        """The fuel stroke fsr0 outside [Vmin, Vmax], and a load limit fsrt0 below it."""
        fsr0 = x["x_act"]
        fsrt0 = jnp.minimum(fsr0 + p["kpload"] * (p["ldref"] / p["kturb"] + p["wfnl"] - fsr0),
                            1.0)
        return super().init_violations(p, x) | {
            "fsr": outside_limits(fsr0, p["vmin"], p["vmax"]),
            "load_limit": fsrt0 < fsr0 - LIMIT_TOL}


GOVERNORS = {m.name: m for m in (Tgov1, Ieeeg1, Wsieg1, Gast, Ieesgo, Hygov, Ggov1)}
