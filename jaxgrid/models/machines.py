"""Synchronous machines: GENCLS, GENROU, GENSAL (and the exponential-saturation GENROE, GENSAE).

Equations, CON orders and initialisation follow `shared/specs/machines-exciters-governors.md`
§0-§3 (PSS/E conventions; OpenIPSL's port for the swing form). Every quantity is per unit on
the machine base MBASE; angles in radians; time constants and H in seconds.

Network interface: a machine is a Norton source behind its subtransient (GENROU, GENSAL) or
transient (GENCLS) impedance `ra + j·xs`. Because X''q = X''d in these models, the Norton
equivalent is exact and no saliency correction is needed. Rotor frame:
`E'' = (ψ''q + j·ψ''d)·exp(j(δ − π/2))`; a current `I` (injected, machine base) maps to
`id + j·iq = I·exp(−j(δ − π/2))`. A model's equations see only the rotor frame
(`emf_rotor`, and the current `to_rotor` gives them); the two rotations happen once per
stage in `jaxgrid.dynamics`, because XLA copies a sin/cos into every fused kernel that reads
it (14 per step, 4 since this split, 39-bus study).
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrid.models.base import (Array, Con, DeviceModel, Initial, Params, Signals, StartPoint,
                                 States, quadratic_saturation, quadratic_saturation_constants,
                                 saturation_problem)
from jaxgrid.vecmath import power, sincos

_H = Con("h", "s", "inertia constant on MBASE (0: infinite bus, GENCLS only)", 0.0)
_D = Con("d", "p.u.", "speed damping", 0.0)


def _t(name: str, info: str) -> Con:
    return Con(name, "s", info, 0.0, positive=True)


def _x(name: str, info: str) -> Con:
    return Con(name, "p.u.", info, 0.0, positive=True)


def to_network_frame(delta):
    """exp(j(δ − π/2)) = sin δ − j·cos δ: rotor (d + jq ordering of the spec) to network
    frame, from `vecmath.sincos` (XLA:CPU's own sine and cosine are scalar code)."""
    sin, cos = sincos(delta)
    return jax.lax.complex(sin, -cos)


def swing(p: Params, x: States, pm, te, omega_b: float) -> States:
    """dδ/dt (rad/s) and dΔω/dt (p.u./s); mechanical power becomes torque via 1/(1 + Δω).

    Units with H = 0 are infinite buses: angle and speed held.
    """
    moving = p["h"] > 0
    h = jnp.where(moving, p["h"], 1.0)
    dw = x["dw"]
    ddw = ((pm - p["d"] * dw) / (1.0 + dw) - te) / (2.0 * h)
    return {"delta": jnp.where(moving, omega_b * dw, 0.0), "dw": jnp.where(moving, ddw, 0.0)}


class MachinePorts(NamedTuple):
    """What a machine reads, arrays (n,).

    Attributes:
      i_dq: injected current, rotor frame, id + j·iq, complex p.u. MBASE.
      efd: field voltage, p.u.
      pm: mechanical power, p.u. MBASE.
      omega_b: base angular frequency, rad/s (Python float).
    """

    i_dq: Array
    efd: Array
    pm: Array
    omega_b: float


class MachineStart(NamedTuple):
    """What a machine starts from at the power flow, arrays (n,).

    Attributes:
      vt: terminal voltage, network frame, complex p.u.
      it: current injected into the bus, network frame, complex p.u. MBASE.
    """

    vt: Array
    it: Array


class MachineModel(DeviceModel):
    """A synchronous machine family. `p` also holds `ra`, `xs` (Norton impedance) and `mbase`."""

    @classmethod
    def ports(cls, signals: Signals, k: Array, flags: States) -> MachinePorts:
        return MachinePorts(i_dq=signals.i_dq[k], efd=signals.efd[k], pm=signals.pm[k],
                            omega_b=signals.omega_b)

    @classmethod
    def source_reactance(cls, p: dict[str, np.ndarray]) -> np.ndarray:
        """The reactance behind which the machine is a Norton source, p.u. MBASE."""
        raise NotImplementedError

    @classmethod
    def init_ports(cls, point: StartPoint, k: Array, labels) -> MachineStart:
        return MachineStart(vt=point.signals.vt[k], it=point.signals.current[k])

    @classmethod
    def init(cls, p: Params, ports: MachineStart) -> Initial:
        """Params and states at rest; output the EFD0, Pm0 (p.u. MBASE) and XadIfd0 that
        exciters and governors start from."""
        p, x, efd0, pm0 = cls.operating_point(p, ports.vt, ports.it)
        xadifd = cls.field_current(p, x, cls.to_rotor(x, ports.it))
        return Initial(p, x, {"efd": efd0, "pm": pm0, "xadifd": xadifd})

    @classmethod
    def operating_point(cls, p: Params, v0, i0) -> tuple[Params, States, Array, Array]:
        """(params, states, EFD0, Pm0) from terminal voltage v0 and injected current i0
        (MBASE), complex (n,)."""
        raise NotImplementedError

    @classmethod
    def emf_rotor(cls, p: Params, x: States):
        """Internal EMF behind `ra + j·xs` in the rotor frame, ψ''q + j·ψ''d, complex (n,)."""
        raise NotImplementedError

    @classmethod
    def emf(cls, p: Params, x: States):
        """Internal EMF behind `ra + j·xs`, network frame, complex (n,)."""
        return cls.emf_rotor(p, x) * to_network_frame(x["delta"])

    @staticmethod
    def to_rotor(x: States, i):
        """The injected current i (n,) (network frame) in the rotor frame, id + j·iq."""
        return i * jnp.conj(to_network_frame(x["delta"]))

    @classmethod
    def rates(cls, p: Params, x: States, ports: MachinePorts) -> tuple[None, States]:
        """(None, state derivatives) at the ports' injected current, EFD and Pm."""
        raise NotImplementedError

    @classmethod
    def field_current(cls, p: Params, x: States, i_dq):
        """XadIfd (p.u.) at the injected current i_dq (rotor frame), for compound-source
        exciters."""
        raise NotImplementedError

    @classmethod
    def electrical_power(cls, p: Params, x: States, i_dq):
        """Air-gap power Te = Re(E''·conj(I)), p.u. MBASE (either frame: i_dq rotor)."""
        return jnp.real(cls.emf_rotor(p, x) * jnp.conj(i_dq))


class Gencls(MachineModel):
    """Classical machine: constant EMF magnitude behind X'd (ZSOURCE of the RAW record)."""

    name = "GENCLS"
    cons = (_H, _D)
    states = ("delta", "dw")

    @classmethod
    def source_reactance(cls, p):
        return p["zx"]

    @classmethod
    def operating_point(cls, p, v0, i0):
        e0 = v0 + (p["ra"] + 1j * p["xs"]) * i0
        p = dict(p, e_mag=jnp.abs(e0))
        x = {"delta": jnp.angle(e0), "dw": jnp.zeros_like(p["h"])}
        return p, x, jnp.zeros_like(p["h"]), jnp.real(e0 * jnp.conj(i0))

    @classmethod
    def emf_rotor(cls, p, x):
        return 1j * p["e_mag"]  # e_mag·exp(jδ) in the network frame

    @classmethod
    def rates(cls, p, x, ports):
        return None, swing(p, x, ports.pm, cls.electrical_power(p, x, ports.i_dq), ports.omega_b)

    @classmethod
    def field_current(cls, p, x, i_dq):
        return jnp.zeros_like(p["h"])


class Genrou(MachineModel):
    """Round-rotor machine with PSS/E quadratic saturation on |ψ''| (spec §1)."""

    name = "GENROU"
    cons = (_t("tpdo", "d-axis transient open-circuit time constant T'do"),
            _t("tppdo", "d-axis subtransient open-circuit time constant T''do"),
            _t("tpqo", "q-axis transient open-circuit time constant T'qo"),
            _t("tppqo", "q-axis subtransient open-circuit time constant T''qo"),
            _H, _D,
            _x("xd", "d-axis synchronous reactance"), _x("xq", "q-axis synchronous reactance"),
            _x("xpd", "d-axis transient reactance X'd"), _x("xpq", "q-axis transient reactance X'q"),
            _x("xppd", "subtransient reactance X''d = X''q"), _x("xl", "leakage reactance"),
            Con("s1", "p.u.", "saturation factor at 1.0 p.u. flux", 0.0),
            Con("s12", "p.u.", "saturation factor at 1.2 p.u. flux", 0.0))
    states = ("eq1", "ed1", "psikd", "psikq", "delta", "dw")
    saturation = staticmethod(quadratic_saturation)

    @classmethod
    def check_combination(cls, p):
        if p["h"] <= 0:
            return f"H = {p['h']:g} s: must be > 0"
        # Xl = X''d is allowed: ψ''d is then ψkd alone ((X''d − Xl)/(X'd − Xl) = 0), and no
        # equation divides by X''d − Xl (ACTIVSg2000's GENSAL at bus 6215 has it)
        if not p["xl"] <= p["xppd"] < p["xpd"] <= p["xd"]:
            return (f"needs Xl <= X''d < X'd <= Xd (Xl = {p['xl']:g}, X''d = {p['xppd']:g}, "
                    f"X'd = {p['xpd']:g}, Xd = {p['xd']:g})")
        if not p["tppdo"] < p["tpdo"]:
            return "needs T''do < T'do"
        return cls.q_axis_problem(p) or cls.saturation_problem(p)

    @classmethod
    def q_axis_problem(cls, p):
        """Why the q-axis data are inconsistent, or None."""
        if not p["xppd"] < p["xpq"] <= p["xq"]:
            return f"needs X''q < X'q <= Xq (X''q = {p['xppd']:g}, X'q = {p['xpq']:g}, Xq = {p['xq']:g})"
        if not p["tppqo"] < p["tpqo"]:
            return "needs T''qo < T'qo"
        return None

    @classmethod
    def saturation_problem(cls, p):
        """Why S(1.0), S(1.2) cannot define the saturation curve, or None."""
        return saturation_problem(1.0, p["s1"], 1.2, p["s12"])

    @classmethod
    def source_reactance(cls, p):
        return p["xppd"]

    @classmethod
    def prepare(cls, p):
        xl, xpd, xppd, xpq = p["xl"], p["xpd"], p["xppd"], p["xpq"]
        a, b = quadratic_saturation_constants(1.0, p["s1"], 1.2, p["s12"])
        return dict(
            p, sat_a=a, sat_b=b,
            k3d=(xppd - xl) / (xpd - xl), k4d=(xpd - xppd) / (xpd - xl),
            k1d=(xpd - xppd) * (p["xd"] - xpd) / (xpd - xl) ** 2,
            k3q=(xppd - xl) / (xpq - xl), k4q=(xpq - xppd) / (xpq - xl),
            k1q=(xpq - xppd) * (p["xq"] - xpq) / (xpq - xl) ** 2,
            gamma=(p["xq"] - xl) / (p["xd"] - xl))

    @classmethod
    def _flux(cls, p, x):
        psi_d = p["k3d"] * x["eq1"] + p["k4d"] * x["psikd"]
        psi_q = p["k3q"] * x["ed1"] + p["k4q"] * x["psikq"]
        return psi_d, psi_q

    @classmethod
    def emf_rotor(cls, p, x):
        psi_d, psi_q = cls._flux(p, x)
        return psi_q + 1j * psi_d

    @classmethod
    def operating_point(cls, p, v0, i0):
        psi0 = v0 + (p["ra"] + 1j * p["xs"]) * i0
        se0 = cls.saturation(jnp.abs(psi0), p["sat_a"], p["sat_b"])
        delta = jnp.angle((1 + p["gamma"] * se0) * psi0 + 1j * (p["xq"] - p["xppd"]) * i0)
        rot = jnp.conj(to_network_frame(delta))
        psi_q, psi_d = jnp.real(psi0 * rot), jnp.imag(psi0 * rot)
        i_d, i_q = jnp.real(i0 * rot), jnp.imag(i0 * rot)
        eq1 = psi_d + (p["xpd"] - p["xppd"]) * i_d
        ed1 = psi_q - (p["xpq"] - p["xppd"]) * i_q
        x = {"eq1": eq1, "ed1": ed1, "psikd": eq1 - (p["xpd"] - p["xl"]) * i_d,
             "psikq": ed1 + (p["xpq"] - p["xl"]) * i_q, "delta": delta,
             "dw": jnp.zeros_like(delta)}
        efd0 = (1 + se0) * psi_d + (p["xd"] - p["xppd"]) * i_d
        return p, x, efd0, jnp.real(psi0 * jnp.conj(i0))

    @classmethod
    def _saturation_terms(cls, p, x):
        """(Se(|ψ''|)·ψ''d, Se(|ψ''|)·ψ''q·γ): extra magnetising effort on each axis."""
        psi_d, psi_q = cls._flux(p, x)
        se = cls.saturation(jnp.sqrt(psi_d ** 2 + psi_q ** 2), p["sat_a"], p["sat_b"])
        return se * psi_d, se * psi_q * p["gamma"]

    @classmethod
    def field_current(cls, p, x, i_dq):
        i_d = jnp.real(i_dq)
        sat_d, _ = cls._saturation_terms(p, x)
        return (x["eq1"] + (p["xd"] - p["xpd"]) * i_d
                + p["k1d"] * (x["eq1"] - x["psikd"] - (p["xpd"] - p["xl"]) * i_d) + sat_d)

    @classmethod
    def rates(cls, p, x, ports):
        i_dq, efd = ports.i_dq, ports.efd
        i_d, i_q = jnp.real(i_dq), jnp.imag(i_dq)
        _, sat_q = cls._saturation_terms(p, x)
        xaqi1q = (x["ed1"] - (p["xq"] - p["xpq"]) * i_q
                  + p["k1q"] * (x["ed1"] - x["psikq"] + (p["xpq"] - p["xl"]) * i_q) + sat_q)
        dx = {"eq1": (efd - cls.field_current(p, x, i_dq)) / p["tpdo"],
              "ed1": -xaqi1q / p["tpqo"],
              "psikd": (x["eq1"] - x["psikd"] - (p["xpd"] - p["xl"]) * i_d) / p["tppdo"],
              "psikq": (x["ed1"] - x["psikq"] + (p["xpq"] - p["xl"]) * i_q) / p["tppqo"]}
        return None, dx | swing(p, x, ports.pm, cls.electrical_power(p, x, i_dq),
                                ports.omega_b)


class Gensal(Genrou):
    """Salient-pole machine, quadratic saturation on E'q only (spec §2)."""

    name = "GENSAL"
    cons = (Genrou.cons[0], Genrou.cons[1], Genrou.cons[3], _H, _D, Genrou.cons[6],
            Genrou.cons[7], Genrou.cons[8], Genrou.cons[10], Genrou.cons[11],
            Genrou.cons[12], Genrou.cons[13])
    states = ("eq1", "psikd", "psiq2", "delta", "dw")

    @classmethod
    def q_axis_problem(cls, p):
        if not p["xppd"] < p["xq"]:
            return f"needs X''q < Xq (X''q = {p['xppd']:g}, Xq = {p['xq']:g})"
        return None

    @classmethod
    def prepare(cls, p):
        return Genrou.prepare(dict(p, xpq=p["xq"], tpqo=p["tppqo"]))

    @classmethod
    def _flux(cls, p, x):
        return p["k3d"] * x["eq1"] + p["k4d"] * x["psikd"], x["psiq2"]

    @classmethod
    def operating_point(cls, p, v0, i0):
        psi0 = v0 + (p["ra"] + 1j * p["xs"]) * i0
        delta = jnp.angle(v0 + (p["ra"] + 1j * p["xq"]) * i0)
        rot = jnp.conj(to_network_frame(delta))
        psi_d = jnp.imag(psi0 * rot)
        i_d, i_q = jnp.real(i0 * rot), jnp.imag(i0 * rot)
        eq1 = psi_d + (p["xpd"] - p["xppd"]) * i_d
        se0 = cls.saturation(eq1, p["sat_a"], p["sat_b"])
        x = {"eq1": eq1, "psikd": eq1 - (p["xpd"] - p["xl"]) * i_d,
             "psiq2": (p["xq"] - p["xppd"]) * i_q, "delta": delta, "dw": jnp.zeros_like(delta)}
        efd0 = eq1 * (1 + se0) + (p["xd"] - p["xpd"]) * i_d
        return p, x, efd0, jnp.real(psi0 * jnp.conj(i0))

    @classmethod
    def field_current(cls, p, x, i_dq):
        i_d = jnp.real(i_dq)
        se = cls.saturation(x["eq1"], p["sat_a"], p["sat_b"])
        return (x["eq1"] + (p["xd"] - p["xpd"]) * i_d
                + p["k1d"] * (x["eq1"] - x["psikd"] - (p["xpd"] - p["xl"]) * i_d) + se * x["eq1"])

    @classmethod
    def rates(cls, p, x, ports):
        i_dq, efd = ports.i_dq, ports.efd
        i_d, i_q = jnp.real(i_dq), jnp.imag(i_dq)
        dx = {"eq1": (efd - cls.field_current(p, x, i_dq)) / p["tpdo"],
              "psikd": (x["eq1"] - x["psikd"] - (p["xpd"] - p["xl"]) * i_d) / p["tppdo"],
              "psiq2": (-x["psiq2"] + (p["xq"] - p["xppd"]) * i_q) / p["tppqo"]}
        return None, dx | swing(p, x, ports.pm, cls.electrical_power(p, x, i_dq),
                                ports.omega_b)


def exponential_saturation(x, n, s1):
    """PSS/E GENROE/GENSAE saturation Se(x) = S(1.0)·x^n with n = ln(S(1.2)/S(1.0))/ln 1.2."""
    return jnp.where(x > 0, s1 * power(jnp.abs(x), n), 0.0)


class _ExponentialSaturation:
    """Mixin: GENROE/GENSAE use S(1.0)·x^n in place of the quadratic curve."""

    saturation = staticmethod(exponential_saturation)

    @classmethod
    def prepare(cls, p):
        p = super().prepare(p)
        with np.errstate(divide="ignore", invalid="ignore"):
            n = np.where(p["s1"] > 0, np.log(p["s12"] / p["s1"]) / np.log(1.2), 0.0)
        return dict(p, sat_a=n, sat_b=p["s1"])

    @classmethod
    def saturation_problem(cls, p):
        if (p["s1"] > 0) != (p["s12"] > 0):
            return "exponential saturation needs S(1.0) and S(1.2) both zero or both > 0"
        return None


class Genroe(_ExponentialSaturation, Genrou):
    name = "GENROE"


class Gensae(_ExponentialSaturation, Gensal):
    name = "GENSAE"


MACHINES = {m.name: m for m in (Gencls, Genrou, Gensal, Genroe, Gensae)}
