"""Excitation systems: IEEET1, IEEEX1, EXDC1, EXDC2, ESDC1A, SEXS, ESST3A, EXST1, ESST1A.

Equations, CON orders and initialisation follow `shared/specs/machines-exciters-governors.md`
§0 and §4-§8 (PSS/E data layouts, IEEE 421.5 block diagrams); EXST1 and ESST1A follow the
PSS/E / IEEE 421.5 ST1A structure described in their classes. Voltages are per unit on the machine base, time
constants in seconds. Every model reads the signals of `ExciterPorts` and returns the field
voltage EFD (p.u.). There are no stabilizer models, so the PSS input Vs is 0 throughout.

Zero time constants bypass their block where the structure allows it (TR, TB/TC, TA, SEXS's TE):
the state is then kept at its initial value, derivative 0, and the block output is algebraic.
Where a division would remain (TE of DC exciters, TF with KF ≠ 0, ESST3A's TM) zero is rejected
when the data are read.
"""
from __future__ import annotations

import dataclasses
from typing import ClassVar, NamedTuple

import jax.numpy as jnp

from jaxgrid.models.base import (Array, Con, DeviceModel, Initial, ModelError, Params, Signals,
                                 StartPoint, States, device_label, freeze_at_limits, lag,
                                 lead_lag_output, outside_limits, quadratic_saturation,
                                 quadratic_saturation_constants, safe, saturation_problem)

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
    """

    ec: Array
    vt: Array
    it: Array
    xadifd: Array
    dw: Array


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
                            xadifd=signals.xadifd[k], dw=signals.dw[k])

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


# --------------------------------------------------------------------------- #
# DC exciters (spec §4-§6)
# --------------------------------------------------------------------------- #

class Ieeet1(ExciterModel):
    """IEEE 1968 type 1 DC exciter (spec §4).

    States: vm (sensed voltage), vr (regulator output, non-windup [VRMIN, VRMAX]), efd (field
    voltage), xf (rate-feedback lag), all p.u. `Switch` must be 0 (other values unverified).
    KE = 0 is used literally (no KE computed at initialisation). Saturation is the quadratic
    curve through (E1, SE1), (E2, SE2) (none if E1 or E2 is 0 or SE1 = SE2 = 0); the extra
    effort Se(EFD)·EFD is 0 for EFD <= 0.
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
        problem = (_order_problem(cls, p, ("vrmin", "vrmax"))
                   or _feedback_problem(cls, p, cls.feedback_tf))
        if problem:
            return problem
        problem = saturation_problem(p["e1"], p["se1"], p["e2"], p["se2"])
        if problem:
            return f"{_label(cls, 'e1', 'se1', 'e2', 'se2')}: {problem}"
        return None

    @classmethod
    def prepare(cls, p):
        a, b = quadratic_saturation_constants(p["e1"], p["se1"], p["e2"], p["se2"])
        return dict(p, sat_a=a, sat_b=b)

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
        sat = jnp.where(efd > 0, efd * quadratic_saturation(efd, p["sat_a"], p["sat_b"]), 0.0)
        return p["ke"] * efd + sat

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
        va, dx_comp = cls.regulator_input(p, x, p["vref"] - vm - vf)
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


# --------------------------------------------------------------------------- #
# Static and simplified exciters (spec §7-§8, EXST1)
# --------------------------------------------------------------------------- #

class Sexs(ExciterModel):
    """Simplified excitation system (spec §7): lead-lag (TA, TB), then K/(1 + sTE) with
    non-windup limits [EMIN, EMAX]. States: xll (lead-lag state), efd, p.u."""

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
    def init(cls, p, start):
        efd0 = start.efd
        u0 = efd0 / p["k"]
        return Initial(dict(p, vref=start.ports.ec + u0), {"xll": u0, "efd": efd0}, {})

    @classmethod
    def rates(cls, p, x, inp):
        u = p["vref"] - inp.ec
        drive = p["k"] * lead_lag_output(x["xll"], u, p["tatb"] * p["tb"], p["tb"])
        efd = jnp.where(p["te"] > 0, x["efd"], jnp.clip(drive, p["emin"], p["emax"]))
        dx = {"xll": lag(x["xll"], u, p["tb"]),
              "efd": freeze_at_limits(lag(x["efd"], drive, p["te"]), x["efd"],
                                      p["emin"], p["emax"])}
        return efd, dx


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
            Con("kc", "p.u.", "rectifier loading factor (commutating reactance)", 0.0),
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
        i_n = jnp.where(ve > 0, p["kc"] * inp.xadifd / safe(ve), 1.0)
        fex = jnp.select(
            [i_n <= 0, i_n <= 0.433, i_n <= 0.75, i_n <= 1.0],
            [jnp.ones_like(i_n), 1.0 - 0.577 * i_n,
             jnp.sqrt(jnp.maximum(0.75 - i_n ** 2, 0.1875)),  # exact where IN <= 0.75
             1.732 * (1.0 - i_n)], 0.0)
        return jnp.minimum(ve * fex, p["vbmax"])

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
        vi = jnp.clip(p["vref"] - vm, p["vimin"], p["vimax"])
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
            Con("kc", "p.u.", "rectifier loading factor", 0.0), _KF, _TF)
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
        vi = jnp.clip(p["vref"] - vm - vf, p["vimin"], p["vimax"])
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

    The ICONs place signals no model here provides: UEL 1-3, where an under-excitation
    limiter's output enters (summing point, HV gate before the lead-lags, HV gate after VA),
    and VOS 1-2, where a stabilizer's (voltage error, after VA). Without those signals the HV
    gates pass VA and every allowed code gives the same model; other codes are refused, as is
    TA = 0 with KF ≠ 0 (algebraic loop through VF). ANDES (the reference of the tests) takes its
    rate feedback before the EFD limiter, the same while the limiter does not bind; its DYR
    reader lists ESST1A values in another order than PSS/E's
    (`experiments.reference.andes_files.andes_dyr`). `init` stores `efd_max0`, the EFD
    ceiling at t = 0, for `init_violations`.
    """

    name = "ESST1A"
    n_icons = 2  # UEL, VOS
    cons = (_TR, _VIMAX, _VIMIN, _TC, _TB,
            dataclasses.replace(_TC, name="tc1", info="second lead-lag numerator time constant"),
            dataclasses.replace(_TB, name="tb1", info="second lead-lag denominator time "
                                                       "constant (0: bypassed)"),
            _KA, _TA,
            Con("vamax", "p.u.", "regulator output VA upper limit"),
            Con("vamin", "p.u.", "regulator output VA lower limit"),
            dataclasses.replace(_VRMAX, info="EFD ceiling per unit Ec (Ec·VRMAX − KC·XadIfd)"),
            dataclasses.replace(_VRMIN, info="EFD floor per unit Ec (Ec·VRMIN)"),
            Con("kc", "p.u.", "rectifier loading factor", 0.0), _KF, _TF,
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
        vm = jnp.where(p["tr"] > 0, x["vm"], inp.ec)
        # VF from the state-based EFD: the output where TA > 0, and KF = 0 elsewhere
        vf = p["kf"] / safe(p["tf"]) * (jnp.clip(x["va"] - vlr, lo, hi) - x["xf"])
        vi = jnp.clip(p["vref"] - vm - vf, p["vimin"], p["vimax"])
        y = lead_lag_output(x["xll"], vi, p["tc"], p["tb"])
        drive = p["ka"] * lead_lag_output(x["xll1"], y, p["tc1"], p["tb1"])
        va = jnp.where(p["ta"] > 0, x["va"], jnp.clip(drive, p["vamin"], p["vamax"]))
        efd = jnp.clip(va - vlr, lo, hi)
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


EXCITERS = {m.name: m for m in (Ieeet1, Ieeex1, Exdc1, Exdc2, Esdc1a, Sexs, Esst3a, Exst1,
                                Esst1a)}
