"""Power system stabilizers: IEEEST.

A stabilizer drives its machine's exciter input VOTHSG (`Signals.vothsg`, the exciters'
`ExciterPorts.vs`, p.u.); its washout makes the output zero at rest, so the exciters start
from their references as without it. Quantities are per unit on the machine base, time
constants in seconds.

IEEEST is the PSS/E IEEE stabilizing model (IEEE 421.5-1992 PSS1A with a fourth-order
filter): ICONs MODE (input signal), IB (remote bus); CONs A1-A6, T1-T6, KS, LSMAX, LSMIN,
VCU, VCL (PSS/E order; the same in PowerSystems.jl's PSS/E reader and ANDES's):

    (1 + A5 s + A6 s²) / ((1 + A1 s + A2 s²)(1 + A3 s + A4 s²))
    · (1 + T1 s)/(1 + T2 s) · (1 + T3 s)/(1 + T4 s) · KS·T5 s/(1 + T6 s)
    -> VSS = clip(·, LSMIN, LSMAX)  (a hard clip of the washout's output),
    VOTHSG = VSS while VCL < Ec < VCU (VCU = 0 or VCL = 0: that side not checked), else 0.
"""
from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax.numpy as jnp
import numpy as np

from jaxgrid.models.base import (Array, Con, DeviceModel, Initial, ModelError, Params,
                                 Sentinel, Signals, StartPoint, States, device_label, lag,
                                 lead_lag_output, safe)

FILTER_ORDER = 4  # filter states per unit, the denominator's largest degree


class StabilizerPorts(NamedTuple):
    """Signals a stabilizer reads from its machine, arrays (n_pss,).

    Attributes:
      dw: speed deviation, p.u.
      pe: electrical power at the terminals, p.u. MBASE.
      pm: mechanical power, p.u. MBASE (its governor's output of the same evaluation).
      ec: terminal voltage magnitude, p.u.
    """

    dw: Array
    pe: Array
    pm: Array
    ec: Array


class StabilizerModel(DeviceModel):
    """A stabilizer family; its rates drive VOTHSG (p.u.), the exciter's VS input."""

    output = "vothsg"

    @classmethod
    def ports(cls, signals: Signals, k: Array, flags: States) -> StabilizerPorts:
        return StabilizerPorts(dw=signals.dw[k], pe=signals.pe[k], pm=signals.pm[k],
                               ec=jnp.abs(signals.vt[k]))

    @classmethod
    def init_ports(cls, point: StartPoint, k: Array, labels) -> StabilizerPorts:
        return cls.ports(point.signals, k, {})


def _degree(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Degree of 1 + first·s + second·s² (0, 1 or 2), per unit."""
    return np.where(second != 0, 2, np.where(first != 0, 1, 0))


class Ieeest(StabilizerModel):
    """PSS/E IEEEST (module docstring for the transfer function and CON order).

    The filter N(s)/D(s), D = (1 + A1 s + A2 s²)(1 + A3 s + A4 s²) of degree n <= 4, is
    realised in controllable canonical form: states f1..fn with f_i' = f_{i+1} and
    a_n·f_n' = u − f1 − a1 f2 − ... − a_{n−1} f_n (a_k D's coefficients), so that f1 is
    the input filtered by 1/D and f1^(k) = f_{k+1}; the output is f1 + A5 f1' + A6 f1''.
    Every unit carries four filter states; those beyond its degree stay zero. The numerator
    may not exceed the denominator's degree, and each denominator factor must be stable
    (A1 > 0 where A2 > 0, A3 > 0 where A4 > 0). Lead-lags: T2 = 0 (T4 = 0) bypasses the
    block and needs T1 = 0 (T3 = 0). States: f1-f4, x_ll1, x_ll2 (lead-lag states), x_wo
    (washout lag), p.u.

    Input signals (MODE): 1 speed deviation, 3 electrical power on MBASE, 4 accelerating
    power Pm − Pe, 5 terminal voltage. 2 (bus frequency) and 6 (derivative of the bus
    voltage) are refused (no frequency or derivative measurement here), as is a remote bus
    IB != 0 with MODE 5; IB plays no role in modes 1, 3 and 4.
    """

    name = "IEEEST"
    n_icons = 2
    stored_icons = ("mode",)
    modes: ClassVar[tuple[int, ...]] = (1, 3, 4, 5)
    cons = (Con("a1", "s", "filter denominator, first factor, s coefficient", 0.0),
            Con("a2", "s²", "filter denominator, first factor, s² coefficient", 0.0),
            Con("a3", "s", "filter denominator, second factor, s coefficient", 0.0),
            Con("a4", "s²", "filter denominator, second factor, s² coefficient", 0.0),
            Con("a5", "s", "filter numerator, s coefficient"),
            Con("a6", "s²", "filter numerator, s² coefficient"),
            Con("t1", "s", "first lead-lag numerator time constant", 0.0),
            Con("t2", "s", "first lead-lag denominator time constant (0: bypassed)", 0.0),
            Con("t3", "s", "second lead-lag numerator time constant", 0.0),
            Con("t4", "s", "second lead-lag denominator time constant (0: bypassed)", 0.0),
            Con("t5", "s", "washout numerator time constant", 0.0),
            Con("t6", "s", "washout denominator time constant", 0.0, positive=True),
            Con("ks", "p.u.", "stabilizer gain"),
            Con("lsmax", "p.u.", "output upper limit"),
            Con("lsmin", "p.u.", "output lower limit"),
            Con("vcu", "p.u.", "output cut-out above this terminal voltage (0: none)", 0.0),
            Con("vcl", "p.u.", "output cut-out below this terminal voltage (0: none)", 0.0,
                sentinel=Sentinel("the output is never cut out (Ec > VCL always)",
                                  lower=True)))
    states = ("f1", "f2", "f3", "f4", "x_ll1", "x_ll2", "x_wo")

    @classmethod
    def check_icons(cls, record, icons):
        mode, bus = icons
        if mode not in cls.modes:
            raise ModelError(f"{device_label(record)}: ICON MODE = {mode:g}: supported input "
                             f"signals {', '.join(map(str, cls.modes))} (1 speed, 3 electrical "
                             "power, 4 accelerating power, 5 terminal voltage); 2 (bus "
                             "frequency) and 6 (voltage derivative) are not modelled")
        if mode == 5 and bus != 0:
            raise ModelError(f"{device_label(record)}: ICON IB = {bus:g} with MODE 5: a remote "
                             "bus voltage is not modelled; use IB = 0")

    @classmethod
    def check_combination(cls, p):
        for first, second, names in ((p["a1"], p["a2"], "A1, A2"), (p["a3"], p["a4"], "A3, A4")):
            if second > 0 and first <= 0:
                return (f"{names} = {first:g}, {second:g}: the filter factor "
                        f"1 + {names[:2]}·s + {names[4:]}·s² is not stable; needs "
                        f"{names[:2]} > 0 where {names[4:]} > 0")
        n = int(_degree(p["a1"], p["a2"]) + _degree(p["a3"], p["a4"]))
        m = int(_degree(p["a5"], p["a6"]))
        if m > n:
            return (f"A5 = {p['a5']:g}, A6 = {p['a6']:g}: the filter numerator's degree {m} "
                    f"exceeds its denominator's {n} (set by A1-A4); not realisable")
        for lead, lag_ in (("t1", "t2"), ("t3", "t4")):
            if p[lag_] == 0 and p[lead] != 0:
                return (f"{lag_.upper()} = 0 with {lead.upper()} = {p[lead]:g}: a pure lead "
                        f"is not realisable; needs {lag_.upper()} > 0 or {lead.upper()} = 0")
        if p["lsmin"] > p["lsmax"]:
            return f"LSMIN = {p['lsmin']:g} > LSMAX = {p['lsmax']:g}"
        return None

    @classmethod
    def prepare(cls, p):
        a1, a2, a3, a4 = p["a1"], p["a2"], p["a3"], p["a4"]
        coefficients = np.stack([a1 + a3, a2 + a4 + a1 * a3, a1 * a4 + a2 * a3, a2 * a4])
        order = _degree(a1, a2) + _degree(a3, a4)
        leading = np.take_along_axis(coefficients, np.maximum(order - 1, 0)[None], 0)[0]
        return dict(p, order=order.astype(float), d1=coefficients[0], d2=coefficients[1],
                    d3=coefficients[2], inv_lead=np.where(order > 0, 1.0 / np.where(
                        order > 0, leading, 1.0), 0.0))

    @classmethod
    def signal(cls, p: Params, ports: StabilizerPorts) -> Array:
        """The input u (n,) p.u. selected by MODE."""
        mode = p["mode"]
        return jnp.where(mode == 1, ports.dw, jnp.where(
            mode == 3, ports.pe, jnp.where(mode == 4, ports.pm - ports.pe, ports.ec)))

    @classmethod
    def filtered(cls, p: Params, x: States, u: Array) -> tuple[Array, dict[str, Array]]:
        """(output of N(s)/D(s) (n,), rates of f1..f4) for input u."""
        n, f = p["order"], [x["f1"], x["f2"], x["f3"], x["f4"]]
        top = (u - f[0] - p["d1"] * f[1] - p["d2"] * f[2] - p["d3"] * f[3]) * p["inv_lead"]
        nxt = f[1:] + [jnp.zeros_like(u)]
        rates = {f"f{i + 1}": jnp.where(n > i + 1, nxt[i], jnp.where(n == i + 1, top, 0.0))
                 for i in range(FILTER_ORDER)}
        # derivatives of f1 = u/D: f1' and f1'' (f_{k+1} below the degree, `top` at it)
        d1, d2 = rates["f1"], jnp.where(n > 2, f[2], jnp.where(n == 2, top, 0.0))
        return jnp.where(n == 0, u, f[0] + p["a5"] * d1 + p["a6"] * d2), rates

    @classmethod
    def init(cls, p, ports):
        u0 = cls.signal(p, ports)
        zero = jnp.zeros_like(u0)
        x = {"f1": jnp.where(p["order"] > 0, u0, 0.0), "f2": zero, "f3": zero, "f4": zero,
             "x_ll1": u0, "x_ll2": u0, "x_wo": u0}
        return Initial(p, x, {})

    @classmethod
    def rates(cls, p, x, ports):
        y, dx = cls.filtered(p, x, cls.signal(p, ports))
        y1 = lead_lag_output(x["x_ll1"], y, p["t1"], p["t2"])
        y2 = lead_lag_output(x["x_ll2"], y1, p["t3"], p["t4"])
        vss = jnp.clip(p["ks"] * p["t5"] / safe(p["t6"]) * (y2 - x["x_wo"]),
                       p["lsmin"], p["lsmax"])
        ec = ports.ec
        on = ((p["vcu"] == 0) | (ec < p["vcu"])) & ((p["vcl"] == 0) | (ec > p["vcl"]))
        dx |= {"x_ll1": lag(x["x_ll1"], y, p["t2"]), "x_ll2": lag(x["x_ll2"], y1, p["t4"]),
               "x_wo": lag(x["x_wo"], y2, p["t6"])}
        return jnp.where(on, vss, 0.0), dx


STABILIZERS = {m.name: m for m in (Ieeest,)}
