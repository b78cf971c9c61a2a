"""Excitation systems: IEEET1, IEEEX1, EXDC1, EXDC2, ESDC1A, ESDC2A, SEXS, SCRX, ESST3A, EXST1,
ESST1A, EXAC1, EXAC2, ESAC1A, ESAC6A, EXPIC1.

Equations, CON orders and initialisation follow `shared/specs/machines-exciters-governors.md`
§0 and §4-§8 (PSS/E data layouts, IEEE 421.5 block diagrams); the models the spec does not
cover follow the PSS/E / IEEE 421.5 structure described in their classes, with the CON order
that PowerSystems.jl's PSS/E DYR reader gives them (checked against ANDES's where it has one).
Voltages are per unit on the machine base, time constants in seconds. Every model reads the
signals of `ExciterPorts` and returns the field voltage EFD (p.u.); the stabilizer's output
VS enters where the model's PSS/E diagram puts VOTHSG (the voltage error unless stated).

Zero time constants bypass their block where the structure allows it (TR, TB/TC, TA, SEXS's TE):
the state is then kept at its initial value, derivative 0, and the block output is algebraic.
Where a division would remain (TE of DC and AC exciters, TF with KF ≠ 0, ESST3A's TM) zero is
rejected when the data are read.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import ClassVar, NamedTuple

import jax.numpy as jnp
import numpy as np

from jaxgrid.models.base import (INF, LIMIT_TOL, Array, Con, DeviceModel, Initial, ModelError,
                                 Params, Signals, StartPoint, States, device_label,
                                 freeze_at_limits, lag, lead_lag_output, outside_limits,
                                 quadratic_saturation_constants, safe)

_TR = Con("tr", "s", "voltage transducer time constant (0: bypassed)", 0.0)
_KA = Con("ka", "p.u.", "regulator gain", 0.0, positive=True)
_TA = Con("ta", "s", "regulator time constant (0: algebraic regulator)", 0.0)
_TB = Con("tb", "s", "lead-lag denominator time constant (0: lead-lag bypassed)", 0.0)
_TC = Con("tc", "s", "lead-lag numerator time constant", 0.0)
_VRMAX = Con("vrmax", "p.u.", "regulator output upper limit")
_VRMIN = Con("vrmin", "p.u.", "regulator output lower limit")
_KE = Con("ke", "p.u.", "exciter field constant (0 is used literally)")
_TE = Con("te", "s", "exciter time constant", 0.0, positive=True)
_KF = Con("kf", "p.u.", "rate feedback gain", 0.0)
_TF = Con("tf", "s", "rate feedback time constant (> 0 unless KF = 0)", 0.0)
_SWITCH = Con("switch", "-", "PSS/E Switch (only 0, the standard model, is supported)")
_SATURATION = (Con("e1", "p.u.", "EFD of the first saturation point", 0.0),
               Con("se1", "p.u.", "saturation factor Se(E1)", 0.0),
               Con("e2", "p.u.", "EFD of the second saturation point", 0.0),
               Con("se2", "p.u.", "saturation factor Se(E2)", 0.0))
_VIMAX = Con("vimax", "p.u.", "voltage error upper limit")
_VIMIN = Con("vimin", "p.u.", "voltage error lower limit")
_VAMAX = Con("vamax", "p.u.", "regulator output VA upper limit")
_VAMIN = Con("vamin", "p.u.", "regulator output VA lower limit")
_KC = Con("kc", "p.u.", "rectifier loading factor (commutating reactance)", 0.0)
_KD = Con("kd", "p.u.", "demagnetizing factor (exciter alternator reactances)", 0.0)


def _label(model: type[DeviceModel], *names: str) -> str:
    """'CON(j) NAME, ...' for CONs of `model`, for error messages."""
    index = {con.name: j + 1 for j, con in enumerate(model.cons)}
    return ", ".join(f"CON({index[n]}) {n.upper()}" for n in names)


def _order_problem(model: type[DeviceModel], p: dict[str, float],
                   *pairs: tuple[str, str]) -> str | None:
    """Why a (lower, upper) limit pair of CONs is reversed, or None."""
    for lo, hi in pairs:
        if p[lo] > p[hi]:
            return f"{_label(model, lo, hi)}: {lo.upper()} = {p[lo]:g} > {hi.upper()} = {p[hi]:g}"
    return None


def _static_problem(model: type[DeviceModel], p: dict[str, float],
                    *pairs: tuple[str, str]) -> str | None:
    """Why an ST1-type exciter's data cannot be used, or None: a reversed limit pair, TF = 0
    with KF ≠ 0, or TA = 0 with KF ≠ 0 (the rate feedback of the algebraic regulator would
    form an algebraic loop)."""
    problem = _order_problem(model, p, *pairs) or _feedback_problem(model, p, "tf")
    if problem is None and p["kf"] != 0 and p["ta"] == 0:
        problem = (f"{_label(model, 'ta')} = 0 s with KF = {p['kf']:g}: the rate feedback of "
                   "the algebraic regulator would form an algebraic loop; needs TA > 0 or "
                   "KF = 0")
    return problem


def _saturation_problem(model: type[DeviceModel], p: dict[str, float]) -> str | None:
    """Why an exciter's saturation points (E1, SE1), (E2, SE2) define no curve, or None.

    [choice] The quadratic Se(x)·x = B(x − A)² is taken as PSS/E's two-point formula gives
    it from the points as written (`quadratic_saturation_constants`): in either order of E,
    and also where its A lies above a point, so that the curve misses that point (then
    there is no saturation below A); both are noted (`_saturation_notes`). The spec's
    stricter rule (0 < E1 < E2, S2·E2 > S1·E1) would refuse 11 of ACTIVSg2000's records.
    Refused: negative values, E1 = E2, SE2 = 0 < SE1 and S1·E1 = S2·E2 (the formula
    divides by zero). SE1 = SE2 = 0 or a zero E: no saturation.
    """
    e1, s1, e2, s2 = p["e1"], p["se1"], p["e2"], p["se2"]
    names = _label(model, "e1", "se1", "e2", "se2")
    if (s1 == 0 and s2 == 0) or e1 == 0 or e2 == 0:
        return None
    if min(e1, s1, e2, s2) < 0:
        return f"{names}: saturation data must be >= 0 ({e1:g}, {s1:g}, {e2:g}, {s2:g})"
    if e1 == e2 or s2 == 0 or s1 * e1 == s2 * e2:
        return (f"{names} = {e1:g}, {s1:g}, {e2:g}, {s2:g}: no quadratic saturation curve "
                "passes through these points (needs E1 != E2, SE2 > 0 and SE1·E1 != SE2·E2)")
    return None


def _saturation_notes(model: type[DeviceModel], p: dict[str, np.ndarray],
                      labels: Sequence[str]) -> list[str]:
    """Notes on saturation points read as `_saturation_problem` allows beyond the spec:
    E1 > E2, and curves whose A lies above a point."""
    a, b = quadratic_saturation_constants(p["e1"], p["se1"], p["e2"], p["se2"])
    out = []
    for k, (e1, s1, e2, s2) in enumerate(zip(p["e1"], p["se1"], p["e2"], p["se2"])):
        if b[k] == 0:
            continue
        label = labels[k] if labels else f"{model.name} unit {k}"
        if e1 > e2:
            out.append(f"{label}: saturation points E1 = {e1:g} > E2 = {e2:g}: read in either "
                       "order (PSS/E's two-point formula)")
        if (s1 > 0 and e1 <= a[k]) or (s2 > 0 and e2 <= a[k]):  # the curve misses a point
            out.append(f"{label}: the saturation curve through ({e1:g}, {s1:g}), ({e2:g}, "
                       f"{s2:g}) has A = {a[k]:.4g} above a point (S·E does not grow with E): "
                       f"read as PSS/E's formula gives it, no saturation below {a[k]:.4g}")
    return out


def _widen(p: Params, value: Array, lo: str, hi: str, scale: Array = 1.0) -> Params:
    """p with the limit CONs lo, hi (per unit of `scale`, e.g. Ec) moved out to the initial
    value `value`/scale where it lies beyond them; the data's values are kept under
    '<name>_data' for `_widened_notes`.

    [choice] The models added for ACTIVSg2000 (SCRX, ESDC2A, EXAC1, EXAC2, ESAC1A, ESAC6A,
    EXPIC1) start this way at rest, as PowerWorld, the tool their data come from, treats a
    start beyond a limit ("If Vr > Vrmax, then Vrmax = Vr", its exciter model pages). The
    spec's models report such a start (InitWarning) instead."""
    v = value / scale
    p = dict(p)
    for name, moved in ((lo, jnp.minimum(p[lo], v)), (hi, jnp.maximum(p[hi], v))):
        p.setdefault(f"{name}_data", p[name])
        p[name] = jnp.where(jnp.isfinite(v), moved, p[name])
    return p


def _widened_notes(model: type[DeviceModel], p: dict[str, np.ndarray],
                   labels: Sequence[str]) -> list[str]:
    """One note per limit `_widen` moved (none before `init`)."""
    out = []
    for key in (k for k in p if k.endswith("_data")):
        name = key[:-len("_data")]
        for k in np.flatnonzero(np.asarray(p[name]) != np.asarray(p[key])):
            label = labels[k] if labels else f"{model.name} unit {k}"
            out.append(f"{label}: the initial value lies beyond {name.upper()} = "
                       f"{float(np.asarray(p[key])[k]):g}: {name.upper()} set to "
                       f"{float(np.asarray(p[name])[k]):.4g} (PowerWorld's rule)")
    return out


def saturation_effort(x: Array, a: Array, b: Array) -> Array:
    """Se(x)·x = B(x − A)² where x > A and x > 0, else 0: the extra excitation of an exciter
    whose output (EFD of a DC exciter, VE of an AC one) is x, p.u."""
    return jnp.where((x > 0) & (x > a), b * (x - a) ** 2, 0.0)


def rectifier_factor(i_n: Array) -> Array:
    """FEX(IN), the rectifier regulation characteristic of IEEE 421.5 (Annex D), elementwise."""
    return jnp.select(
        [i_n <= 0, i_n <= 0.433, i_n <= 0.75, i_n <= 1.0],
        [jnp.ones_like(i_n), 1.0 - 0.577 * i_n,
         jnp.sqrt(jnp.maximum(0.75 - i_n ** 2, 0.1875)),  # exact where IN <= 0.75
         1.732 * (1.0 - i_n)], 0.0)


def rectifier_output(ve: Array, kc_ifd: Array) -> Array:
    """VE·FEX(KC·IFD/VE), p.u.: a rectifier's output from its source voltage VE; 0 where
    VE <= 0."""
    return ve * rectifier_factor(jnp.where(ve > 0, kc_ifd / jnp.where(ve > 0, ve, 1.0), 1.0))


def rectifier_source(efd: Array, kc_ifd: Array) -> Array:
    """The VE > 0 with `rectifier_output(VE, kc_ifd)` = efd (> 0): FEX's three branches
    inverted, the one whose IN = kc_ifd/VE falls in its range taken."""
    linear = efd + 0.577 * kc_ifd
    circle = jnp.sqrt((efd ** 2 + kc_ifd ** 2) / 0.75)
    return jnp.where(kc_ifd <= 0.433 * linear, linear,
                     jnp.where(kc_ifd <= 0.75 * circle, circle, efd / 1.732 + kc_ifd))


def _feedback_problem(model: type[DeviceModel], p: dict[str, float], tf: str) -> str | None:
    """Why the rate feedback KF·s/(1 + s·TF) cannot be built (TF = 0 with KF ≠ 0), or None."""
    if p["kf"] != 0 and p[tf] <= 0:
        return (f"{_label(model, tf)} = {p[tf]:g} s with KF = {p['kf']:g}: "
                "the rate feedback divides by it; must be > 0")
    return None


class ExciterPorts(NamedTuple):
    """Signals an exciter reads from its machine, arrays (n_exc,).

    Attributes:
      ec: terminal voltage magnitude, p.u.
      vt: terminal voltage phasor, network frame, complex p.u.
      it: machine current injected into the bus, network frame, complex p.u. on MBASE.
      xadifd: field current XadIfd, p.u.
      dw: speed deviation, p.u.
      vs: the stabilizer's output VOTHSG, p.u. (0 without a stabilizer; 0 at rest).
    """

    ec: Array
    vt: Array
    it: Array
    xadifd: Array
    dw: Array
    vs: Array


class ExciterStart(NamedTuple):
    """What an exciter starts from: the field voltage efd (n,) p.u. it holds at rest and
    its ports at the power flow (dw = 0)."""

    efd: Array
    ports: ExciterPorts


class ExciterModel(DeviceModel):
    """An excitation-system family; `p` holds the CONs and, after `init`, `vref` (p.u.).
    Its rates drive the machine's field voltage EFD (p.u.)."""

    output = "efd"

    @classmethod
    def ports(cls, signals: Signals, k: Array, flags: States) -> ExciterPorts:
        return ExciterPorts(ec=jnp.abs(signals.vt[k]), vt=signals.vt[k], it=signals.current[k],
                            xadifd=signals.xadifd[k], dw=signals.dw[k], vs=signals.vothsg[k])

    @classmethod
    def init_ports(cls, point: StartPoint, k: Array, labels) -> ExciterStart:
        return ExciterStart(efd=point.signals.efd[k], ports=cls.ports(point.signals, k, {}))

    @classmethod
    def init(cls, p: Params, start: ExciterStart) -> Initial:
        """Params with `vref` and states holding EFD = start.efd at equilibrium (no output)."""
        raise NotImplementedError

    @classmethod
    def rates(cls, p: Params, x: States, inp: ExciterPorts) -> tuple[Array, States]:
        """(EFD (n,) p.u., {state: derivative per second})."""
        raise NotImplementedError


class _SaturatedExciter(ExciterModel):
    """An exciter with saturation CONs E1, SE(E1), E2, SE(E2) (`_saturation_problem`):
    `prepare` adds the curve's sat_a, sat_b; `notes` reports the saturation readings and
    the limits `_widen` moved."""

    @classmethod
    def prepare(cls, p):
        a, b = quadratic_saturation_constants(p["e1"], p["se1"], p["e2"], p["se2"])
        return dict(p, sat_a=a, sat_b=b)

    @classmethod
    def notes(cls, p, labels=()):
        return _saturation_notes(cls, p, labels) + _widened_notes(cls, p, labels)


# --------------------------------------------------------------------------- #
# DC exciters (spec §4-§6)
# --------------------------------------------------------------------------- #

class Ieeet1(_SaturatedExciter):
    """IEEE 1968 type 1 DC exciter (spec §4).

    States: vm (sensed voltage), vr (regulator output, non-windup [VRMIN, VRMAX]), efd (field
    voltage), xf (rate-feedback lag), all p.u. `Switch` must be 0 (other values unverified).
    KE = 0 is used literally (no KE computed at initialisation). Saturation is the quadratic
    curve through (E1, SE1), (E2, SE2) (none if E1 or E2 is 0 or SE1 = SE2 = 0; read as
    `_saturation_problem` says); the extra effort Se(EFD)·EFD is 0 for EFD <= 0.
    """

    name = "IEEET1"
    cons = (_TR, _KA, _TA, _VRMAX, _VRMIN, _KE, _TE, _KF, _TF, _SWITCH) + _SATURATION
    states = ("vm", "vr", "efd", "xf")
    feedback_tf: ClassVar[str] = "tf"  # name of the rate-feedback time constant CON

    @classmethod
    def check_combination(cls, p):
        if p["switch"] != 0:
            return (f"{_label(cls, 'switch')} = {p['switch']:g}: only 0 (the standard model) "
                    "is supported; the meaning of other values is unverified")
        return (_order_problem(cls, p, ("vrmin", "vrmax"))
                or _feedback_problem(cls, p, cls.feedback_tf) or _saturation_problem(cls, p))

    @classmethod
    def limits(cls, p):
        return {"vr": (p["vrmin"], p["vrmax"])}

    @classmethod
    def regulator_bounds(cls, p: Params, ec: Array) -> tuple[Array, Array]:
        """(lo, hi) of the regulator output VR, p.u., at terminal voltage ec."""
        return p["vrmin"], p["vrmax"]

    @classmethod
    def regulator_input(cls, p: Params, x: States, u: Array) -> tuple[Array, States]:
        """(VA, derivatives of compensator states) for the voltage error u; VA = u here."""
        return u, {}

    @classmethod
    def field_effort(cls, p: Params, efd: Array) -> Array:
        """(KE + Se(EFD))·EFD, p.u."""
        return p["ke"] * efd + saturation_effort(efd, p["sat_a"], p["sat_b"])

    @classmethod
    def init(cls, p, start):
        efd0, ec = start.efd, start.ports.ec
        vr0 = cls.field_effort(p, efd0)
        x = {"vm": ec, "vr": vr0, "efd": efd0, "xf": efd0}
        return Initial(dict(p, vref=ec + vr0 / p["ka"]), x, {})

    @classmethod
    def rates(cls, p, x, inp):
        vm = jnp.where(p["tr"] > 0, x["vm"], inp.ec)
        vf = p["kf"] / safe(p[cls.feedback_tf]) * (x["efd"] - x["xf"])
        va, dx_comp = cls.regulator_input(p, x, p["vref"] - vm - vf + inp.vs)
        lo, hi = cls.regulator_bounds(p, inp.ec)
        drive = p["ka"] * va
        vr = jnp.clip(jnp.where(p["ta"] > 0, x["vr"], drive), lo, hi)
        dx = {"vm": lag(x["vm"], inp.ec, p["tr"]),
              "vr": freeze_at_limits(lag(x["vr"], drive, p["ta"]), x["vr"], lo, hi),
              "efd": (vr - cls.field_effort(p, x["efd"])) / p["te"],
              "xf": lag(x["xf"], x["efd"], p[cls.feedback_tf])}
        return x["efd"], dx_comp | dx

    @classmethod
    def init_violations(cls, p, x):
        # x["vm"] is Ec at t = 0 whatever TR
        return {"vr": outside_limits(x["vr"], *cls.regulator_bounds(p, x["vm"]))}


class Ieeex1(Ieeet1):
    """IEEE 1979 type 1 / 1981 DC1 exciter (spec §5): IEEET1 with a lead-lag (TC, TB) before
    the regulator; extra state xll (lead-lag state, p.u.). The feedback time constant is TF1."""

    name = "IEEEX1"
    cons = (_TR, _KA, _TA, _TB, _TC, _VRMAX, _VRMIN, _KE, _TE, _KF,
            dataclasses.replace(_TF, name="tf1"), _SWITCH) + _SATURATION
    states = ("vm", "xll", "vr", "efd", "xf")
    feedback_tf = "tf1"

    @classmethod
    def regulator_input(cls, p, x, u):
        return (lead_lag_output(x["xll"], u, p["tc"], p["tb"]),
                {"xll": lag(x["xll"], u, p["tb"])})

    @classmethod
    def init(cls, p, start):
        p, x, out, *_ = super().init(p, start)
        return Initial(p, {"xll": x["vr"] / p["ka"]} | x, out)


class Exdc1(Ieeex1):
    """EXDC1: not a PSS/E library name; reference files use it for the IEEEX1 structure with
    the same 16 CONs (spec §5), as GridPACK reads it."""

    name = "EXDC1"


class Exdc2(Ieeex1):
    """IEEE 1981 DC2 (spec §5): IEEEX1 with regulator limits VRMIN·Ec, VRMAX·Ec.

    The limits move with Ec, so the integrator does not clip vr (no static `limits`): the
    derivative is frozen at the scaled limits and the output is clipped to them. When Ec drops
    below the level at which vr was frozen, the state may sit above the new ceiling until the
    error reverses (bounded by the earlier ceiling). ANDES puts this scaling on IEEEX1 instead.
    """

    name = "EXDC2"

    @classmethod
    def limits(cls, p):
        return {}

    @classmethod
    def regulator_bounds(cls, p, ec):
        return p["vrmin"] * ec, p["vrmax"] * ec


class Esdc1a(Ieeex1):
    """IEEE 421.5-2005 DC1A (spec §6): the IEEEX1 numerics with non-windup VR limits; the
    UEL/OEL inputs are inactive (no limiter models), no speed multiplier on EFD."""

    name = "ESDC1A"


class Esdc2a(Exdc2):
    """IEEE 421.5-2005 DC2A, PSS/E ESDC2A (CON order TR, KA, TA, TB, TC, VRMAX, VRMIN, KE,
    TE, KF, TF1, Switch, E1, SE(E1), E2, SE(E2): IEEEX1's, as PowerSystems.jl's and ANDES's
    readers have it): DC1A with non-windup regulator limits VRMAX·Ec, VRMIN·Ec, which is
    EXDC2's structure here (the limits move with Ec). UEL/OEL inactive, no speed multiplier.
    A regulator output that starts beyond its limits moves them (`_widen`, noted)."""

    name = "ESDC2A"

    @classmethod
    def init(cls, p, start):
        initial = super().init(p, start)
        return initial._replace(params=_widen(initial.params, initial.states["vr"], "vrmin",
                                              "vrmax", start.ports.ec))


# --------------------------------------------------------------------------- #
# Static and simplified exciters (spec §7-§8, EXST1)
# --------------------------------------------------------------------------- #

class Sexs(ExciterModel):
    """Simplified excitation system (spec §7): lead-lag (TA, TB), then K/(1 + sTE) with
    non-windup limits [EMIN, EMAX]. States: xll (lead-lag state), efd (the limited lag's
    output E, which is EFD here; `field_voltage`), p.u."""

    name = "SEXS"
    cons = (Con("tatb", "-", "lead-lag time constant ratio TA/TB", 0.0),
            dataclasses.replace(_TB, info="lead-lag denominator time constant (0: bypassed)"),
            Con("k", "p.u.", "gain", 0.0, positive=True),
            Con("te", "s", "exciter time constant (0: algebraic, EFD = clip(K·y))", 0.0),
            Con("emin", "p.u.", "EFD lower limit"),
            Con("emax", "p.u.", "EFD upper limit"))
    states = ("xll", "efd")

    @classmethod
    def check_combination(cls, p):
        return _order_problem(cls, p, ("emin", "emax"))

    @classmethod
    def limits(cls, p):
        return {"efd": (p["emin"], p["emax"])}

    @classmethod
    def field_voltage(cls, p: Params, e: Array, inp: ExciterPorts) -> Array:
        """EFD (n,) p.u. from E, the limited lag's output: E itself."""
        return e

    @classmethod
    def lag_output(cls, p: Params, efd: Array, inp: ExciterPorts) -> Array:
        """The E that gives EFD = efd at the ports inp (`field_voltage` inverted)."""
        return efd

    @classmethod
    def init(cls, p, start):
        e0 = cls.lag_output(p, start.efd, start.ports)
        u0 = e0 / p["k"]
        return Initial(dict(p, vref=start.ports.ec + u0), {"xll": u0, "efd": e0}, {})

    @classmethod
    def rates(cls, p, x, inp):
        u = p["vref"] - inp.ec + inp.vs
        drive = p["k"] * lead_lag_output(x["xll"], u, p["tatb"] * p["tb"], p["tb"])
        e = jnp.where(p["te"] > 0, x["efd"], jnp.clip(drive, p["emin"], p["emax"]))
        dx = {"xll": lag(x["xll"], u, p["tb"]),
              "efd": freeze_at_limits(lag(x["efd"], drive, p["te"]), x["efd"],
                                      p["emin"], p["emax"])}
        return cls.field_voltage(p, e, inp), dx


class Scrx(Sexs):
    """PSS/E SCRX bus- or solid-fed static exciter (PSS/E CON order TA/TB, TB, K, TE, EMIN,
    EMAX, CSWITCH, rc/rfd, as PowerSystems.jl's and ANDES's readers have it): SEXS's lead-lag
    and limited lag give E in [EMIN, EMAX]; EX = E·Ec bus-fed (CSWITCH = 0) or E solid-fed
    (CSWITCH = 1); EFD = EX, except that an exciter without negative-current capability
    (rc/rfd > 0, the field discharge resistance over the field resistance) gives
    EFD = −rc/rfd·XadIfd while the field current is not positive (PSS/E's negative current
    logic, as PowerSimulationsDynamics.jl implements it). States as SEXS: xll, efd (E). An
    E that starts beyond [EMIN, EMAX] moves the limit (`_widen`, noted)."""

    name = "SCRX"
    cons = Sexs.cons + (Con("cswitch", "-", "0: bus fed (E·Ec), 1: solid fed", 0.0, 1.0),
                        Con("rcrfd", "-", "rc/rfd: 0 with negative field current capability, "
                            "> 0 without", 0.0))

    @classmethod
    def check_combination(cls, p):
        if p["cswitch"] not in (0.0, 1.0):
            return f"{_label(cls, 'cswitch')} = {p['cswitch']:g}: allowed 0 (bus fed), 1 (solid fed)"
        return super().check_combination(p)

    @classmethod
    def supply(cls, p: Params, inp: ExciterPorts) -> Array:
        """The multiplier of E: Ec bus-fed, 1 solid-fed."""
        return jnp.where(p["cswitch"] == 0, inp.ec, 1.0)

    @classmethod
    def field_voltage(cls, p, e, inp):
        blocked = (p["rcrfd"] > 0) & (inp.xadifd <= 0)
        return jnp.where(blocked, -p["rcrfd"] * inp.xadifd, e * cls.supply(p, inp))

    @classmethod
    def lag_output(cls, p, efd, inp):
        return efd / cls.supply(p, inp)

    @classmethod
    def init(cls, p, start):
        initial = super().init(p, start)
        return initial._replace(params=_widen(initial.params, initial.states["efd"], "emin",
                                              "emax"))

    @classmethod
    def notes(cls, p, labels=()):
        return _widened_notes(cls, p, labels)


class Esst3a(ExciterModel):
    """IEEE 421.5 ST3A potential/compound-source exciter with inner field-voltage loop (spec §8).

    States: vm (sensed voltage), xll (lead-lag state), vr (regulator, non-windup [VRMIN, VRMAX];
    algebraic when TA = 0), vm_inner (inner-loop output VM, non-windup [VMMIN, VMMAX]), p.u.
    EFD = VB·VM with VB from the terminal phasors and the field current (FEX rectifier curve).
    """

    name = "ESST3A"
    cons = (_TR, _VIMAX, _VIMIN,
            Con("km", "p.u.", "inner-loop forward gain", 0.0, positive=True),
            _TC, _TB, _KA, _TA, _VRMAX, _VRMIN,
            Con("kg", "p.u.", "inner-loop feedback gain", 0.0),
            Con("kp", "p.u.", "potential circuit gain", 0.0),
            Con("ki", "p.u.", "potential circuit (current) gain", 0.0),
            Con("vbmax", "p.u.", "maximum available exciter voltage", 0.0),
            _KC,
            Con("xl", "p.u.", "reactance of the potential source", 0.0),
            Con("vgmax", "p.u.", "inner-loop feedback upper limit", 0.0),
            Con("thetap", "deg", "potential circuit phase angle", -180.0, 180.0),
            Con("tm", "s", "inner-loop time constant", 0.0, positive=True),
            Con("vmmax", "p.u.", "inner-loop output upper limit"),
            Con("vmmin", "p.u.", "inner-loop output lower limit"))
    states = ("vm", "xll", "vr", "vm_inner")

    @classmethod
    def check_combination(cls, p):
        return _order_problem(cls, p, ("vimin", "vimax"), ("vrmin", "vrmax"), ("vmmin", "vmmax"))

    @classmethod
    def limits(cls, p):
        return {"vr": (p["vrmin"], p["vrmax"]), "vm_inner": (p["vmmin"], p["vmmax"])}

    @classmethod
    def exciter_voltage(cls, p: Params, inp: ExciterPorts) -> Array:
        """VB = min(VE·FEX(IN), VBMAX), p.u.; 0 where VE = 0."""
        kpc = p["kp"] * jnp.exp(1j * jnp.deg2rad(p["thetap"]))
        ve = jnp.abs(kpc * inp.vt + 1j * (p["ki"] + kpc * p["xl"]) * inp.it)
        return jnp.minimum(rectifier_output(ve, p["kc"] * inp.xadifd), p["vbmax"])

    @classmethod
    def init(cls, p, start):
        efd0, inp = start
        vm_inner = efd0 / cls.exciter_voltage(p, inp)  # inf/NaN where VB0 = 0: a violation
        vr0 = vm_inner / p["km"] + jnp.minimum(p["kg"] * efd0, p["vgmax"])
        vi0 = vr0 / p["ka"]
        x = {"vm": inp.ec, "xll": vi0, "vr": vr0, "vm_inner": vm_inner}
        return Initial(dict(p, vref=inp.ec + vi0), x, {})

    @classmethod
    def rates(cls, p, x, inp):
        vm = jnp.where(p["tr"] > 0, x["vm"], inp.ec)
        vi = jnp.clip(p["vref"] - vm + inp.vs, p["vimin"], p["vimax"])
        drive_r = p["ka"] * lead_lag_output(x["xll"], vi, p["tc"], p["tb"])
        vr = jnp.where(p["ta"] > 0, x["vr"], jnp.clip(drive_r, p["vrmin"], p["vrmax"]))
        efd = cls.exciter_voltage(p, inp) * x["vm_inner"]
        drive_m = p["km"] * (vr - jnp.minimum(p["kg"] * efd, p["vgmax"]))
        dx = {"vm": lag(x["vm"], inp.ec, p["tr"]),
              "xll": lag(x["xll"], vi, p["tb"]),
              "vr": freeze_at_limits(lag(x["vr"], drive_r, p["ta"]), x["vr"],
                                     p["vrmin"], p["vrmax"]),
              "vm_inner": freeze_at_limits(lag(x["vm_inner"], drive_m, p["tm"]), x["vm_inner"],
                                           p["vmmin"], p["vmmax"])}
        return efd, dx

    @classmethod
    def init_violations(cls, p, x):
        # xll holds Vi0 at t = 0 whatever TB
        return super().init_violations(p, x) | {"vi": outside_limits(x["xll"], p["vimin"],
                                                                     p["vimax"])}


class Exst1(ExciterModel):
    """PSS/E EXST1 / IEEE ST1A static exciter (not in the spec; PSS/E CON order).

    Vi = clip(Vref − Vm − VF, VIMIN, VIMAX); lead-lag (TC, TB) → VLL; TA dVR/dt = KA·VLL − VR
    (unlimited; VR = KA·VLL when TA = 0); EFD = clip(VR, Ec·VRMIN, Ec·VRMAX − KC·XadIfd) as in
    IEEE ST1A (ANDES omits the Ec factor); VF = KF·s/(1 + sTF) of EFD. States: vm, xll, vr,
    xf (rate-feedback lag), p.u. TA = 0 with KF ≠ 0 is rejected (algebraic loop through VF).
    `init` also stores `efd_max0`, the EFD ceiling at t = 0, for `init_violations`.
    """

    name = "EXST1"
    cons = (_TR, _VIMAX, _VIMIN, _TC, _TB, _KA, _TA, _VRMAX, _VRMIN,
            _KC, _KF, _TF)
    states = ("vm", "xll", "vr", "xf")

    @classmethod
    def check_combination(cls, p):
        return _static_problem(cls, p, ("vimin", "vimax"), ("vrmin", "vrmax"))

    @classmethod
    def output_bounds(cls, p: Params, inp: ExciterPorts) -> tuple[Array, Array]:
        """(lo, hi) of EFD, p.u.: Ec·VRMIN, Ec·VRMAX − KC·XadIfd."""
        return inp.ec * p["vrmin"], inp.ec * p["vrmax"] - p["kc"] * inp.xadifd

    @classmethod
    def init(cls, p, start):
        efd0, inp = start
        vi0 = efd0 / p["ka"]
        x = {"vm": inp.ec, "xll": vi0, "vr": efd0, "xf": efd0}
        p = dict(p, vref=inp.ec + vi0, efd_max0=cls.output_bounds(p, inp)[1])
        return Initial(p, x, {})

    @classmethod
    def rates(cls, p, x, inp):
        lo, hi = cls.output_bounds(p, inp)
        vm = jnp.where(p["tr"] > 0, x["vm"], inp.ec)
        # VF from the state-based EFD: identical to the output where TA > 0, and KF = 0 elsewhere
        vf = p["kf"] / safe(p["tf"]) * (jnp.clip(x["vr"], lo, hi) - x["xf"])
        vi = jnp.clip(p["vref"] - vm - vf + inp.vs, p["vimin"], p["vimax"])
        drive = p["ka"] * lead_lag_output(x["xll"], vi, p["tc"], p["tb"])
        efd = jnp.clip(jnp.where(p["ta"] > 0, x["vr"], drive), lo, hi)
        dx = {"vm": lag(x["vm"], inp.ec, p["tr"]),
              "xll": lag(x["xll"], vi, p["tb"]),
              "vr": lag(x["vr"], drive, p["ta"]),
              "xf": lag(x["xf"], efd, p["tf"])}
        return efd, dx

    @classmethod
    def init_violations(cls, p, x):
        # at t = 0: vm = Ec, xll = Vi0, vr = EFD0
        return {"vi": outside_limits(x["xll"], p["vimin"], p["vimax"]),
                "efd": outside_limits(x["vr"], x["vm"] * p["vrmin"], p["efd_max0"])}


class Esst1a(ExciterModel):
    """PSS/E ESST1A / IEEE 421.5-2005 ST1A static exciter (not in the spec; PSS/E ICON and CON
    order: UEL, VOS; TR, VIMAX, VIMIN, TC, TB, TC1, TB1, KA, TA, VAMAX, VAMIN, VRMAX, VRMIN,
    KC, KF, TF, KLR, ILR).

    Vi = clip(Vref − Vm − VF, VIMIN, VIMAX); lead-lags (TC, TB) then (TC1, TB1) → VLL;
    TA dVA/dt = KA·VLL − VA, non-windup [VAMIN, VAMAX] (VA = clip(KA·VLL) when TA = 0); the
    field-current limiter VLR = KLR·max(XadIfd − ILR, 0); EFD = clip(VA − VLR, Ec·VRMIN,
    Ec·VRMAX − KC·XadIfd) (the EXST1 output limits); VF = KF·s/(1 + sTF) of EFD. States: vm,
    xll, xll1 (the two lead-lag states), va, xf (rate-feedback lag), p.u.

    The ICON VOS places the stabilizer's output VS: 1 at the summing point (voltage error),
    2 added to VA (before the field-current limiter). UEL 1-3 place an under-excitation
    limiter's output (summing point, HV gate before the lead-lags, HV gate after VA); no
    such model exists here, so the HV gates pass VA and every UEL code gives the same model.
    Other codes are refused, as is TA = 0 with KF ≠ 0 (algebraic loop through VF). ANDES (the reference of the tests) takes its
    rate feedback before the EFD limiter, the same while the limiter does not bind; its DYR
    reader lists ESST1A values in another order than PSS/E's
    (`experiments.reference.andes_files.andes_dyr`). `init` stores `efd_max0`, the EFD
    ceiling at t = 0, for `init_violations`.
    """

    name = "ESST1A"
    n_icons = 2
    stored_icons = ("uel", "vos")
    cons = (_TR, _VIMAX, _VIMIN, _TC, _TB,
            dataclasses.replace(_TC, name="tc1", info="second lead-lag numerator time constant"),
            dataclasses.replace(_TB, name="tb1", info="second lead-lag denominator time "
                                                       "constant (0: bypassed)"),
            _KA, _TA, _VAMAX, _VAMIN,
            dataclasses.replace(_VRMAX, info="EFD ceiling per unit Ec (Ec·VRMAX − KC·XadIfd)"),
            dataclasses.replace(_VRMIN, info="EFD floor per unit Ec (Ec·VRMIN)"),
            _KC, _KF, _TF,
            Con("klr", "p.u.", "field-current limiter gain", 0.0),
            Con("ilr", "p.u.", "field-current limiter pickup XadIfd"))
    states = ("vm", "xll", "xll1", "va", "xf")
    icon_codes = {"UEL": (1, 2, 3), "VOS": (1, 2)}

    @classmethod
    def check_icons(cls, record, icons):
        for (name, allowed), value in zip(cls.icon_codes.items(), icons):
            if value not in allowed:
                raise ModelError(f"{device_label(record)}: ICON {name} = {value:g}: PSS/E "
                                 f"defines {', '.join(map(str, allowed))}; other codes are "
                                 "not supported")

    @classmethod
    def check_combination(cls, p):
        return _static_problem(cls, p, ("vimin", "vimax"), ("vamin", "vamax"),
                               ("vrmin", "vrmax"))

    @classmethod
    def limits(cls, p):
        return {"va": (p["vamin"], p["vamax"])}

    @classmethod
    def current_limit(cls, p: Params, xadifd: Array) -> Array:
        """VLR = KLR·max(XadIfd − ILR, 0), p.u."""
        return p["klr"] * jnp.maximum(xadifd - p["ilr"], 0.0)

    @classmethod
    def init(cls, p, start):
        efd0, inp = start
        va0 = efd0 + cls.current_limit(p, inp.xadifd)
        vi0 = va0 / p["ka"]
        x = {"vm": inp.ec, "xll": vi0, "xll1": vi0, "va": va0, "xf": efd0}
        p = dict(p, vref=inp.ec + vi0, efd_max0=Exst1.output_bounds(p, inp)[1])
        return Initial(p, x, {})

    @classmethod
    def rates(cls, p, x, inp):
        lo, hi = Exst1.output_bounds(p, inp)
        vlr = cls.current_limit(p, inp.xadifd)
        vs_sum, vs_va = jnp.where(p["vos"] == 1, inp.vs, 0.0), jnp.where(p["vos"] == 2, inp.vs, 0.0)
        vm = jnp.where(p["tr"] > 0, x["vm"], inp.ec)
        # VF from the state-based EFD: the output where TA > 0, and KF = 0 elsewhere
        vf = p["kf"] / safe(p["tf"]) * (jnp.clip(x["va"] + vs_va - vlr, lo, hi) - x["xf"])
        vi = jnp.clip(p["vref"] - vm - vf + vs_sum, p["vimin"], p["vimax"])
        y = lead_lag_output(x["xll"], vi, p["tc"], p["tb"])
        drive = p["ka"] * lead_lag_output(x["xll1"], y, p["tc1"], p["tb1"])
        va = jnp.where(p["ta"] > 0, x["va"], jnp.clip(drive, p["vamin"], p["vamax"]))
        efd = jnp.clip(va + vs_va - vlr, lo, hi)
        dx = {"vm": lag(x["vm"], inp.ec, p["tr"]),
              "xll": lag(x["xll"], vi, p["tb"]),
              "xll1": lag(x["xll1"], y, p["tb1"]),
              "va": freeze_at_limits(lag(x["va"], drive, p["ta"]), x["va"],
                                     p["vamin"], p["vamax"]),
              "xf": lag(x["xf"], efd, p["tf"])}
        return efd, dx

    @classmethod
    def init_violations(cls, p, x):
        # at t = 0: vm = Ec, xll = Vi0, xf = EFD0
        return super().init_violations(p, x) | {
            "vi": outside_limits(x["xll"], p["vimin"], p["vimax"]),
            "efd": outside_limits(x["xf"], x["vm"] * p["vrmin"], p["efd_max0"])}


# --------------------------------------------------------------------------- #
# AC (alternator-rectifier) exciters and the PI regulator EXPIC1
# --------------------------------------------------------------------------- #

class _Alternator(_SaturatedExciter):
    """The exciter alternator and rectifier of the IEEE 421.5 AC types, shared by EXAC1,
    EXAC2, ESAC1A and ESAC6A: TE dVE/dt = VR − VFE, non-windup VE >= 0 (OpenIPSL's PSS/E
    models; IEEE 421.5-2005 draws the limit for AC1A-AC6A), VFE = KE·VE + Se(VE)·VE +
    KD·XadIfd, EFD = VE·FEX(KC·XadIfd/VE) (`rectifier_output`). No speed multiplier.
    Regulator outputs that start beyond their limits move them (`_widen`, noted). Families
    set `cons`, `states` (with "ve") and the regulator."""

    @classmethod
    def field_feedback(cls, p: Params, ve: Array, xadifd: Array) -> Array:
        """VFE (n,) p.u., the exciter field current."""
        return p["ke"] * ve + saturation_effort(ve, p["sat_a"], p["sat_b"]) + p["kd"] * xadifd

    @classmethod
    def alternator(cls, p: Params, ve0: Array, vr: Array, vfe: Array) -> Array:
        """dVE/dt (n,) p.u./s at regulator output vr, non-windup at VE = 0."""
        return freeze_at_limits((vr - vfe) / p["te"], ve0, 0.0, INF)

    @classmethod
    def start(cls, p: Params, start: ExciterStart) -> tuple[Array, Array]:
        """(VE0, VFE0) holding EFD0 at start."""
        ve0 = rectifier_source(start.efd, p["kc"] * start.ports.xadifd)
        return ve0, cls.field_feedback(p, ve0, start.ports.xadifd)


class Exac1(_Alternator):
    """PSS/E EXAC1, IEEE 1981 type AC1 (PSS/E CON order TR, TB, TC, KA, TA, VRMAX, VRMIN, TE,
    KF, TF, KC, KD, KE, E1, SE(E1), E2, SE(E2), as PowerSystems.jl's and ANDES's readers
    have it).

    Vm = Ec/(1 + sTR); lead-lag (TC, TB) of Vref − Vm − VF + VS; KA/(1 + sTA) with
    non-windup limits (VRMIN, VRMAX for EXAC1) gives the amplifier output VA, from which
    `regulator` forms VR (EXAC1: VR = VA); the alternator (`_Alternator`); the rate feedback
    VF = KF·s/(1 + sTF) of VFE (IEEE, PSS/E and OpenIPSL; GridKit takes it from VE).
    States: vm, xll (lead-lag), va, ve, xf (rate-feedback lag), p.u.
    """

    name = "EXAC1"
    cons = (_TR, _TB, _TC, _KA, _TA, _VRMAX, _VRMIN, _TE, _KF, _TF, _KC, _KD, _KE) + _SATURATION
    states = ("vm", "xll", "va", "ve", "xf")
    amplifier: ClassVar[tuple[str, str]] = ("vrmin", "vrmax")  # the CONs limiting VA
    ordered: ClassVar[tuple[tuple[str, str], ...]] = (("vrmin", "vrmax"),)

    @classmethod
    def check_combination(cls, p):
        return (_order_problem(cls, p, *cls.ordered) or _feedback_problem(cls, p, "tf")
                or _saturation_problem(cls, p))

    @classmethod
    def limits(cls, p):
        lo, hi = cls.amplifier
        return {"va": (p[lo], p[hi]), "ve": (0.0, INF)}

    @classmethod
    def regulator(cls, p: Params, va: Array, vfe: Array) -> Array:
        """VR (n,) p.u. from the amplifier output VA and VFE."""
        return va

    @classmethod
    def amplifier_output(cls, p: Params, vfe: Array) -> Array:
        """The VA that holds VR = VFE (at rest)."""
        return vfe

    @classmethod
    def widen(cls, p: Params, va0: Array, vfe0: Array) -> Params:
        """p with the limits VA0 (and VR0 = VFE0) start beyond moved (`_widen`)."""
        return _widen(p, va0, *cls.amplifier)

    @classmethod
    def init(cls, p, start):
        ve0, vfe0 = cls.start(p, start)
        va0 = cls.amplifier_output(p, vfe0)
        ec = start.ports.ec
        x = {"vm": ec, "xll": va0 / p["ka"], "va": va0, "ve": ve0, "xf": vfe0}
        return Initial(dict(cls.widen(p, va0, vfe0), vref=ec + va0 / p["ka"]), x, {})

    @classmethod
    def rates(cls, p, x, inp):
        lo, hi = cls.limits(p)["va"]
        vm = jnp.where(p["tr"] > 0, x["vm"], inp.ec)
        vfe = cls.field_feedback(p, x["ve"], inp.xadifd)
        u = p["vref"] - vm - p["kf"] / safe(p["tf"]) * (vfe - x["xf"]) + inp.vs
        drive = p["ka"] * lead_lag_output(x["xll"], u, p["tc"], p["tb"])
        va = jnp.where(p["ta"] > 0, x["va"], jnp.clip(drive, lo, hi))
        dx = {"vm": lag(x["vm"], inp.ec, p["tr"]),
              "xll": lag(x["xll"], u, p["tb"]),
              "va": freeze_at_limits(lag(x["va"], drive, p["ta"]), x["va"], lo, hi),
              "ve": cls.alternator(p, x["ve"], cls.regulator(p, va, vfe), vfe),
              "xf": lag(x["xf"], vfe, p["tf"])}
        return rectifier_output(x["ve"], p["kc"] * inp.xadifd), dx


class Exac2(Exac1):
    """PSS/E EXAC2, IEEE 1981 type AC2 (PSS/E CON order TR, TB, TC, KA, TA, VAMAX, VAMIN,
    KB, VRMAX, VRMIN, TE, KL, KH, KF, TF, KC, KD, KE, VLR, E1, SE(E1), E2, SE(E2), as
    PowerSystems.jl's and ANDES's readers have it): EXAC1 with VA within [VAMIN, VAMAX] and
    VR = clip(KB·min(VA − KH·VFE, KL·(VLR − VFE)), VRMIN, VRMAX), the low-value gate
    between the regulator path and the field-current limiter (ANDES's reading; GridKit's
    signs differ). A start where the limiter path is the lower is reported (`lv_gate`)."""

    name = "EXAC2"
    cons = (_TR, _TB, _TC, _KA, _TA, _VAMAX, _VAMIN,
            Con("kb", "p.u.", "second stage regulator gain", 0.0, positive=True),
            _VRMAX, _VRMIN, _TE,
            Con("kl", "p.u.", "field-current limiter gain", 0.0),
            Con("kh", "p.u.", "exciter field current feedback gain", 0.0),
            _KF, _TF, _KC, _KD, _KE,
            Con("vlr", "p.u.", "field-current limiter reference VFE")) + _SATURATION
    amplifier = ("vamin", "vamax")
    ordered = (("vamin", "vamax"), ("vrmin", "vrmax"))

    @classmethod
    def regulator(cls, p, va, vfe):
        gate = jnp.minimum(va - p["kh"] * vfe, p["kl"] * (p["vlr"] - vfe))
        return jnp.clip(p["kb"] * gate, p["vrmin"], p["vrmax"])

    @classmethod
    def amplifier_output(cls, p, vfe):
        return vfe / p["kb"] + p["kh"] * vfe

    @classmethod
    def widen(cls, p, va0, vfe0):
        return _widen(super().widen(p, va0, vfe0), vfe0, "vrmin", "vrmax")

    @classmethod
    def init_violations(cls, p, x):
        vfe0 = x["xf"]  # at t = 0
        return super().init_violations(p, x) | {
            "vr": outside_limits(vfe0, p["vrmin"], p["vrmax"]),
            "lv_gate": vfe0 / p["kb"] > p["kl"] * (p["vlr"] - vfe0) + LIMIT_TOL}


class Esac1a(Exac1):
    """PSS/E ESAC1A, IEEE 421.5-2005 AC1A (PSS/E CON order TR, TB, TC, KA, TA, VAMAX, VAMIN,
    TE, KF, TF, KC, KD, KE, E1, SE(E1), E2, SE(E2), VRMAX, VRMIN, as PowerSystems.jl's
    reader has it; ANDES 2.0's reader takes another order,
    `experiments.reference.andes_files.andes_dyr`): EXAC1 with VA within [VAMIN, VAMAX] and
    VR = clip(VA, VRMIN, VRMAX) (the UEL/OEL gates pass VA: no limiter models)."""

    name = "ESAC1A"
    cons = (_TR, _TB, _TC, _KA, _TA, _VAMAX, _VAMIN, _TE, _KF, _TF, _KC, _KD, _KE
            ) + _SATURATION + (_VRMAX, _VRMIN)
    amplifier = ("vamin", "vamax")
    ordered = (("vamin", "vamax"), ("vrmin", "vrmax"))

    @classmethod
    def regulator(cls, p, va, vfe):
        return jnp.clip(va, p["vrmin"], p["vrmax"])

    @classmethod
    def widen(cls, p, va0, vfe0):
        return _widen(super().widen(p, va0, vfe0), vfe0, "vrmin", "vrmax")

    @classmethod
    def init_violations(cls, p, x):
        return super().init_violations(p, x) | {
            "vr": outside_limits(x["xf"], p["vrmin"], p["vrmax"])}


class Esac6a(_Alternator):
    """PSS/E ESAC6A, IEEE 421.5-2005 AC6A (PSS/E CON order TR, KA, TA, TK, TB, TC, VAMAX,
    VAMIN, VRMAX, VRMIN, TE, VFELIM, KH, VHMAX, TH, TJ, KC, KD, KE, E1, SE(E1), E2, SE(E2),
    as PowerSystems.jl's and ANDES's readers have it; ANDES implements no ESAC6A).

    Vm = Ec/(1 + sTR); VA = KA(1 + sTK)/(1 + sTA) of Vref − Vm + VS, non-windup within
    [VAMIN, VAMAX] (its lag state frozen while VA is at a limit and the state would push it
    further; TA = 0: VA = clip(KA·u), TK must be 0); VLL = (1 + sTC)/(1 + sTB) of VA; the
    field-current limiter VH = clip(KH·(1 + sTJ)/(1 + sTH) of (VFE − VFELIM), 0, VHMAX);
    VR = clip(VLL − VH, Ec·VRMIN, Ec·VRMAX) (limits proportional to the terminal voltage,
    IEEE 421.5-2005); the alternator (`_Alternator`). No rate feedback. VA and VR that
    start beyond their limits move them (`_widen`, noted). States: vm, xa (lag of the KA
    block), xll, ve, xh (limiter lag), p.u.
    """

    name = "ESAC6A"
    cons = (_TR, _KA, _TA, Con("tk", "s", "regulator lead time constant", 0.0), _TB, _TC,
            _VAMAX, _VAMIN,
            dataclasses.replace(_VRMAX, info="regulator output upper limit per unit Ec"),
            dataclasses.replace(_VRMIN, info="regulator output lower limit per unit Ec"),
            _TE, Con("vfelim", "p.u.", "field-current limiter reference VFE"),
            Con("kh", "p.u.", "field-current limiter gain", 0.0),
            Con("vhmax", "p.u.", "field-current limiter output upper limit", 0.0),
            Con("th", "s", "field-current limiter lag time constant (0: bypassed)", 0.0),
            Con("tj", "s", "field-current limiter lead time constant", 0.0),
            _KC, _KD, _KE) + _SATURATION
    states = ("vm", "xa", "xll", "ve", "xh")

    @classmethod
    def check_combination(cls, p):
        for lead, lag_ in (("tk", "ta"), ("tj", "th")):
            if p[lag_] == 0 and p[lead] != 0:
                return (f"{_label(cls, lag_)} = 0 with {lead.upper()} = {p[lead]:g}: a pure lead "
                        f"is not realisable; needs {lag_.upper()} > 0 or {lead.upper()} = 0")
        return (_order_problem(cls, p, ("vamin", "vamax"), ("vrmin", "vrmax"))
                or _saturation_problem(cls, p))

    @classmethod
    def limits(cls, p):
        return {"ve": (0.0, INF)}

    @classmethod
    def limiter(cls, p: Params, x: States, vfe: Array) -> tuple[Array, Array]:
        """(VH (n,) p.u., dxh/dt) of the field-current limiter at VFE."""
        u = vfe - p["vfelim"]
        vh = jnp.clip(p["kh"] * lead_lag_output(x["xh"], u, p["tj"], p["th"]), 0.0, p["vhmax"])
        return vh, lag(x["xh"], u, p["th"])

    @classmethod
    def init(cls, p, start):
        ve0, vfe0 = cls.start(p, start)
        ec = start.ports.ec
        va0 = vfe0 + jnp.clip(p["kh"] * (vfe0 - p["vfelim"]), 0.0, p["vhmax"])
        x = {"vm": ec, "xa": va0 / p["ka"], "xll": va0, "ve": ve0, "xh": vfe0 - p["vfelim"]}
        p = _widen(_widen(p, va0, "vamin", "vamax"), vfe0, "vrmin", "vrmax", ec)
        return Initial(dict(p, vref=ec + va0 / p["ka"]), x, {})

    @classmethod
    def rates(cls, p, x, inp):
        vm = jnp.where(p["tr"] > 0, x["vm"], inp.ec)
        u = p["vref"] - vm + inp.vs
        drive = p["ka"] * lead_lag_output(x["xa"], u, p["tk"], p["ta"])
        va = jnp.clip(drive, p["vamin"], p["vamax"])
        dxa = lag(x["xa"], u, p["ta"])
        push = dxa * (1.0 - p["tk"] / safe(p["ta"]))  # the sign the state moves VA with
        frozen = ((drive >= p["vamax"]) & (push > 0)) | ((drive <= p["vamin"]) & (push < 0))
        vfe = cls.field_feedback(p, x["ve"], inp.xadifd)
        vh, dxh = cls.limiter(p, x, vfe)
        vr = jnp.clip(lead_lag_output(x["xll"], va, p["tc"], p["tb"]) - vh,
                      inp.ec * p["vrmin"], inp.ec * p["vrmax"])
        dx = {"vm": lag(x["vm"], inp.ec, p["tr"]),
              "xa": jnp.where(frozen, 0.0, dxa),
              "xll": lag(x["xll"], va, p["tb"]),
              "ve": cls.alternator(p, x["ve"], vr, vfe),
              "xh": dxh}
        return rectifier_output(x["ve"], p["kc"] * inp.xadifd), dx

    @classmethod
    def init_violations(cls, p, x):
        # at t = 0: vm = Ec, xll = VA0, xh = VFE0 − VFELIM
        vfe0, ec = x["xh"] + p["vfelim"], x["vm"]
        return super().init_violations(p, x) | {
            "va": outside_limits(x["xll"], p["vamin"], p["vamax"]),
            "vr": outside_limits(vfe0, ec * p["vrmin"], ec * p["vrmax"])}


class Expic1(_SaturatedExciter):
    """PSS/E EXPIC1 proportional/integral exciter (PSS/E CON order TR, KA, TA1, VR1, VR2,
    TA2, TA3, TA4, VRMAX, VRMIN, KF, TF1, TF2, EFDMAX, EFDMIN, KE, TE, E1, SE(E1), E2,
    SE(E2), KP, KI, KC, as PowerSystems.jl's and ANDES's readers have it; ANDES implements
    no EXPIC1).

    Vm = Ec/(1 + sTR); the PI regulator KA(1 + sTA1)/s of Vref − Vm − VF + VS, non-windup
    within [VR2, VR1] (its integral frozen while the output is at a limit and the error
    pushes it further) -> VA; VR = clip((1 + sTA3)/((1 + sTA2)(1 + sTA4)) of VA, VRMIN,
    VRMAX) (the lead paired with TA4, or with TA2 where TA4 = 0); the source VB =
    VE·FEX(KC·XadIfd/VE), VE = |KP·Vt + j·KI·It| (VB = 1 where KP = KI = 0); E0 =
    clip(VB·VR, EFDMIN, EFDMAX); TE dEFD/dt = E0 − (KE + Se(EFD))·EFD, or EFD = E0 where
    TE = 0; the rate feedback VF = KF·s/((1 + sTF1)(1 + sTF2)) of VR (GridKit's and
    OPAL-RT's reading of the PSS/E diagram). KF != 0 needs TF1, TF2 > 0 (otherwise its
    direct path closes an algebraic loop through the PI's proportional gain). VA, VR and
    E0 that start beyond their limits move them (`_widen`, noted). States: vm, xi (PI
    integral), x2 (lag), x3 (lead-lag), xf1, xf2 (feedback lags), efd, p.u. `init` stores
    `e00`, E0 at t = 0, for `init_violations`.
    """

    name = "EXPIC1"
    cons = (_TR, Con("ka", "p.u.", "PI regulator gain (integral gain, 1/s)", 0.0, positive=True),
            Con("ta1", "s", "PI lead time constant (proportional gain KA·TA1)", 0.0),
            Con("vr1", "p.u.", "PI output upper limit"),
            Con("vr2", "p.u.", "PI output lower limit"),
            Con("ta2", "s", "regulator filter lag time constant", 0.0),
            Con("ta3", "s", "regulator filter lead time constant", 0.0),
            Con("ta4", "s", "regulator filter second lag time constant", 0.0),
            _VRMAX, _VRMIN, _KF,
            Con("tf1", "s", "rate feedback first lag time constant", 0.0),
            Con("tf2", "s", "rate feedback second lag time constant", 0.0),
            Con("efdmax", "p.u.", "exciter input E0 upper limit"),
            Con("efdmin", "p.u.", "exciter input E0 lower limit"),
            _KE, Con("te", "s", "exciter time constant (0: EFD = E0)", 0.0)) + _SATURATION + (
            Con("kp", "p.u.", "potential source gain", 0.0),
            Con("ki", "p.u.", "current source gain", 0.0), _KC)
    states = ("vm", "xi", "x2", "x3", "xf1", "xf2", "efd")

    @classmethod
    def check_combination(cls, p):
        if p["ta2"] == 0 and p["ta4"] == 0 and p["ta3"] != 0:
            return (f"{_label(cls, 'ta2', 'ta4')} = 0 with TA3 = {p['ta3']:g}: a pure lead is "
                    "not realisable; needs TA2 or TA4 > 0, or TA3 = 0")
        if p["kf"] != 0 and (p["tf1"] <= 0 or p["tf2"] <= 0):
            return (f"{_label(cls, 'tf1', 'tf2')} = {p['tf1']:g}, {p['tf2']:g} with KF = "
                    f"{p['kf']:g}: the rate feedback needs TF1 > 0 and TF2 > 0")
        return (_order_problem(cls, p, ("vr2", "vr1"), ("vrmin", "vrmax"), ("efdmin", "efdmax"))
                or _saturation_problem(cls, p))

    @classmethod
    def prepare(cls, p):
        paired = p["ta4"] > 0
        return dict(super().prepare(p), t_ll=np.where(paired, p["ta4"], p["ta2"]),
                    t_lag=np.where(paired, p["ta2"], 0.0))

    @classmethod
    def limits(cls, p):
        return {"xi": (p["vr2"], p["vr1"])}

    @classmethod
    def source(cls, p: Params, inp: ExciterPorts) -> Array:
        """VB (n,) p.u., the potential/current source after the rectifier."""
        ve = jnp.abs(p["kp"] * inp.vt + 1j * p["ki"] * inp.it)
        none = (p["kp"] == 0) & (p["ki"] == 0)
        return jnp.where(none, 1.0, rectifier_output(ve, p["kc"] * inp.xadifd))

    @classmethod
    def exciter_input(cls, p: Params, efd: Array) -> Array:
        """(KE + Se(EFD))·EFD where TE > 0 (the E0 that holds EFD), else EFD."""
        effort = p["ke"] * efd + saturation_effort(efd, p["sat_a"], p["sat_b"])
        return jnp.where(p["te"] > 0, effort, efd)

    @classmethod
    def init(cls, p, start):
        efd0, inp = start
        e00 = cls.exciter_input(p, efd0)
        vr0 = e00 / cls.source(p, inp)  # inf/NaN where VB0 = 0: a violation
        x = {"vm": inp.ec, "xi": vr0, "x2": vr0, "x3": vr0, "xf1": vr0,
             "xf2": jnp.zeros_like(vr0), "efd": efd0}
        p = _widen(_widen(_widen(p, vr0, "vr2", "vr1"), vr0, "vrmin", "vrmax"), e00, "efdmin",
                   "efdmax")
        return Initial(dict(p, vref=inp.ec, e00=e00), x, {})

    @classmethod
    def rates(cls, p, x, inp):
        vm = jnp.where(p["tr"] > 0, x["vm"], inp.ec)
        u = p["vref"] - vm - x["xf2"] + inp.vs
        pi = x["xi"] + p["ka"] * p["ta1"] * u
        va = jnp.clip(pi, p["vr2"], p["vr1"])
        y = lead_lag_output(x["x3"], va, p["ta3"], p["t_ll"])
        vr = jnp.clip(jnp.where(p["t_lag"] > 0, x["x2"], y), p["vrmin"], p["vrmax"])
        e0 = jnp.clip(cls.source(p, inp) * vr, p["efdmin"], p["efdmax"])
        efd = jnp.where(p["te"] > 0, x["efd"], e0)
        effort = p["ke"] * efd + saturation_effort(efd, p["sat_a"], p["sat_b"])
        dx = {"vm": lag(x["vm"], inp.ec, p["tr"]),
              "xi": freeze_at_limits(p["ka"] * u, pi, p["vr2"], p["vr1"]),
              "x2": lag(x["x2"], y, p["t_lag"]),
              "x3": lag(x["x3"], va, p["t_ll"]),
              "xf1": lag(x["xf1"], vr, p["tf1"]),
              "xf2": lag(x["xf2"], p["kf"] / safe(p["tf1"]) * (vr - x["xf1"]), p["tf2"]),
              "efd": jnp.where(p["te"] > 0, (e0 - effort) / safe(p["te"]), 0.0)}
        return efd, dx

    @classmethod
    def init_violations(cls, p, x):
        # at t = 0: x2 = VR0 (before its limits)
        return super().init_violations(p, x) | {
            "vr": outside_limits(x["x2"], p["vrmin"], p["vrmax"]),
            "e0": outside_limits(p["e00"], p["efdmin"], p["efdmax"])}


EXCITERS = {m.name: m for m in (Ieeet1, Ieeex1, Exdc1, Exdc2, Esdc1a, Esdc2a, Sexs, Scrx, Esst3a,
                                Exst1, Esst1a, Exac1, Exac2, Esac1a, Esac6a, Expic1)}
