"""Three-phase induction-motor loads CIM5BL and CIM6BL (PSS/E), one motor per RAW load record.

Equations, CON orders and initialisation follow `shared/specs/induction-motors.md`: the
PSS/E-structured form of §4 (stator transients neglected; transient EMF E', second-cage
flux ψk, rotor speed ω), whose constants (§3.1) make its steady state equal to the exact
double-cage circuit `Z(s) = RA + jXA + [jXM ∥ (R1/s + jX1) ∥ (R2/s + jX2)]` at every slip;
the load torque of §4 (CIM5: T0·ω^D, CIM6: T0·(Aω² + Bω + C0 + Dω^E)); the one-stage
under-voltage trip of §7. Reactances and powers are per unit on the motor base Sm, H in
seconds on Sm, TI and TB in cycles (converted to seconds with the nominal frequency).

Complex quantities are phasors in the network frame; states are their real and imaginary
parts (`epr`, `epi` for E', `psir`, `psii` for ψk) and the speed `w` (p.u.). The motor is a
Norton source: it draws `status·(Sm/Sbase)·(V − E'')/(RA + j·Lpp)`, so `y_norton =
(Sm/Sbase)/(RA + j·Lpp)` is folded into the network matrix (spec §8).

Choices ([choice] and [unverified] points of the spec; each substitution is listed in the
load report):
  * Standard simplification (spec §6, pitfall 6): a second cage whose T''0 is below
    `options.stiff_below` (default 0.01 s = 2 × a 5 ms step) is dropped, Lpp := Lp, because
    an explicit step cannot follow it; the slip is re-solved for the simplified motor so it
    still draws the record's P, and the report gives the slip the full motor would have.
  * IT = 2 (spec §3.2, [unverified] circuit) is accepted with the §3.2 constants and noted.
  * The slip bracket of §5 ends at the first maximum of the air-gap torque (breakdown),
    not of the input power: between the two (they differ by RA·|I|²) a constant-torque load
    has no stable operating point.
  * Saturation (§3.3, quadratic form [unverified]) is on only when E1, E2, SE(E1) and
    SE(E2) are all > 0; partial data switch it off and are reported.
  * CIM6 C0 is computed at initialisation (§1.2, [medium confidence]); a different file
    value is reported. TNOM only serves motor starting and is ignored.
  * The load torque uses max(ω, `W_TORQUE_MIN`) in ω^D and ω^E, so a stalled motor
    (ω = 0, spec §4 speed floor) has finite torque and gradients for any exponent.
  * Timers fire within a hundredth of a step of their setting (float32 round-off of
    the accumulated time; `base.timer_fires`).
CIMWBL is not supported: its CON list is unverified (spec §1.3).

Step size: the slip rotation −j·ωb·s·E' makes a stalled motor (s → 1, |ωb·s| ≈ 377 1/s)
unstable under plain Heun at 5 ms (growth ≈ 1.9 per step), and the stator's short-circuit
decay (≈ (Ls/Lp)/T'0, some 100-200 1/s) is stiff as well. Both are linear in E' (and ψk) at a
fixed bus voltage, so `stiff_rates` declares them and the step integrates them exactly
(exponential Heun, `jaxgrid.dynamics`): the step size is then set by accuracy, not by a
stalled motor's stability.
"""
from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from jaxgrid.records import DyrRecord
from jaxgrid.models.options import MotorOptions
from jaxgrid.models.base import (Array, Con, Initial, LoadModel, LoadPorts, LoadSite, ModelError,
                                 Params, States,
                                 device_label, quadratic_saturation,
                                 quadratic_saturation_constants, safe, saturation_problem,
                                 timer_fires)
from jaxgrid.vecmath import power

SLIP_MIN = 1e-7             # smallest slip of the initialisation bracket (spec §5)
SLIP_GRID = 700             # log-spaced slips in [SLIP_MIN, 1] scanned for breakdown
BISECTIONS = 100            # most halvings of the slip bracket (it stops at float64 resolution)
GOLDEN_STEPS = 60           # golden-section steps refining the breakdown slip
SAT_BISECTIONS = 64         # halvings of the Se(|E''|) bracket in the steady state
W_TORQUE_MIN = 1e-3         # p.u.: speed floor inside ω^D and ω^E of the load torque
MOTOR_STATES = ("epr", "epi", "psir", "psii", "w")  # one motor's continuous states
C0_REPORT_TOL = 1e-6        # |file C0 − computed C0| above which the report mentions it


def _pu(name: str, info: str, positive: bool = False) -> Con:
    return Con(name, "p.u.", info, 0.0, positive=positive)


_CIRCUIT = (
    _pu("ra", "stator resistance RA"),
    _pu("xa", "stator leakage reactance XA (Ll of the equations)"),
    _pu("xm", "magnetising reactance XM", positive=True),
    _pu("r1", "first-cage rotor resistance R1", positive=True),
    _pu("x1", "first-cage rotor leakage reactance X1"),
    _pu("r2", "second-cage resistance R2 (0: single cage)"),
    _pu("x2", "second-cage reactance X2 (0: single cage)"),
    _pu("e1", "first saturation point E1, |E''| (0: no saturation)"),
    Con("se1", "-", "saturation factor SE(E1)", 0.0),
    _pu("e2", "second saturation point E2, |E''|"),
    Con("se2", "-", "saturation factor SE(E2)", 0.0),
    Con("mbase", "MVA", "motor base Sm (0: PMULT × the load record's MW)", 0.0),
    Con("pmult", "MVA/MW", "motor base per MW of load, used when MBASE = 0", 0.0),
    Con("h", "s", "inertia constant on Sm", 0.0, positive=True),
    _pu("vi", "under-voltage trip pickup VI (0: no trip)"),
    Con("ti", "cycles", "time below VI before the relay picks up", 0.0),
    Con("tb", "cycles", "breaker delay after pickup", 0.0),
)
_TNOM = Con("tnom", "p.u.", "load torque at 1 p.u. speed for motor starting (ignored)")


class Cim5bl(LoadModel):
    """CIM5BL: induction motor (type 1 or [unverified] type 2), load torque T0·ω^D.

    `read` adds `it` (the ICON IT) to the CON arrays; `init` adds the derived constants:
    sm (Sm/Sbase), omega_b (rad/s), ls, lp, lpp, ll (p.u. Sm), tp0, tpp0 (s), k3, k4, k5,
    double (1: second cage modelled), sat_a, sat_b, ti_s, tb_s (s), t0 (torque base, p.u.
    Sm) and y_norton (complex, p.u. system base).

    Attributes (states, arrays (n,)):
      epr, epi: transient EMF E', network frame, p.u.
      psir, psii: second-cage flux ψk, network frame, p.u. (held for a single cage).
      w: rotor speed, p.u. of synchronous speed (slip s = 1 − w).
    Flags (arrays (n,)): t_low, t_brk: time below VI and since pickup, s; picked: relay
    picked up (0/1, latched); status: motor connected (0/1, latched at 0 after a trip).
    """

    name = "CIM5BL"
    n_icons = 1
    cons = _CIRCUIT + (Con("d", "-", "load-torque speed exponent: TL = T0·ω^D"), _TNOM)
    states = ("epr", "epi", "psir", "psii", "w")
    flags = ("t_low", "picked", "t_brk", "status")

    # ------------------------------------------------------------------ #
    # Data (host)
    # ------------------------------------------------------------------ #

    @classmethod
    def read(cls, records: Sequence[DyrRecord]) -> dict[str, np.ndarray]:
        """CON arrays (n,) float64 plus `it`, the motor type (1 or 2)."""
        p = super().read(records)
        p["it"] = np.array([float(r.cons[0]) for r in records])
        for k, rec in enumerate(records):
            if p["it"][k] == 2 and not (p["r2"][k] > 0 and p["x2"][k] > 0):
                raise ModelError(f"{device_label(rec)}: IT = 2 (deep-bar ladder) needs both "
                                 f"cages (R2 = {p['r2'][k]:g}, X2 = {p['x2'][k]:g})")
        return p

    @classmethod
    def check_icons(cls, record: DyrRecord, icons) -> None:
        (it,) = icons
        if it not in (1, 2):
            raise ModelError(f"{device_label(record)}: ICON IT = {it:g}: allowed 1 (cages in "
                             f"parallel) or 2 (deep-bar ladder)")

    @classmethod
    def check_combination(cls, p):
        if p["mbase"] == 0 and p["pmult"] == 0:
            return "MBASE = PMULT = 0: the motor base is undefined"
        if p["r2"] > 0 and p["x2"] > 0 and p["x1"] == 0:
            return "X1 = 0 with a second cage (R2, X2 > 0): L' or L'' would equal XA"
        if p["ra"] == 0 and p["xa"] == 0 and p["x1"] == 0:
            return "RA = XA = X1 = 0: the stator impedance RA + jL'' is zero"
        if _saturated(p["e1"], p["se1"], p["e2"], p["se2"]):
            return saturation_problem(p["e1"], p["se1"], p["e2"], p["se2"])
        return None

    # ------------------------------------------------------------------ #
    # Load torque (overridden by CIM6BL)
    # ------------------------------------------------------------------ #

    @classmethod
    def torque_constants(cls, p: dict, w0: np.ndarray, te0: np.ndarray) -> tuple[dict, list]:
        """(constants for `load_torque`, [(unit, note)]) so that TL(ω0) = Te0 (host, NumPy)."""
        return {"t0": te0 / w0 ** p["d"]}, []

    @classmethod
    def load_torque(cls, p: Params, w: Array) -> Array:
        """Mechanical load torque TL(ω), p.u. on Sm: T0·ω^D."""
        return p["t0"] * power(jnp.maximum(w, W_TORQUE_MIN), p["d"])

    # ------------------------------------------------------------------ #
    # Initialisation (host, NumPy float64)
    # ------------------------------------------------------------------ #

    @classmethod
    def init(cls, p: Params, site: LoadSite) -> Initial:
        """Params, states, flags, output {s0} and load report at the power flow (spec §2, §5).

        The whole load record is the motor: it draws P = site.record_p at site.v0 and the
        Q of its equivalent circuit. site.motors.stiff_below (s; None: MotorOptions()): see
        the module docstring. Raises ModelError naming the unit when the motor cannot carry
        its load at V0.
        """
        stiff_below = (site.motors or MotorOptions()).stiff_below
        p = {k: np.asarray(v, dtype=float) for k, v in p.items()}
        n = p["ra"].shape[0]
        v0 = np.asarray(site.v0, dtype=complex)
        p_load = np.asarray(site.record_p, dtype=float)
        _raise_all([f"{site.label(k)}: the load record draws P = {p_load[k] * site.sbase:g} "
                    f"MW at V0; a motor needs P > 0" for k in np.flatnonzero(~(p_load > 0))])
        sm = np.where(p["mbase"] > 0, p["mbase"] / site.sbase, p["pmult"] * p_load)
        omega_b = np.full(n, 2 * np.pi * site.f_nom)
        full = motor_constants(p, omega_b, stiff_below=0.0)
        used = motor_constants(p, omega_b, stiff_below=stiff_below)
        dropped = (full["double"] > 0) & (used["double"] == 0)
        sat_on = _saturated(p["e1"], p["se1"], p["e2"], p["se2"])
        sat_a, sat_b = quadratic_saturation_constants(p["e1"], p["se1"], p["e2"], p["se2"])
        sat_a, sat_b = np.where(sat_on, sat_a, 0.0), np.where(sat_on, sat_b, 0.0)
        c = dict(p, **used, sat_a=sat_a, sat_b=sat_b, sm=sm, omega_b=omega_b)

        target = p_load / sm  # motor p.u.
        vmag = np.abs(v0)
        s0, problem = solve_slip(c, vmag, target)
        _raise_all([f"{site.label(k)}: motor cannot carry its load at V0 = {vmag[k]:.4f} "
                    f"p.u.: {problem[k]} (a larger MBASE or PMULT lowers the load per unit "
                    f"of the motor base)" for k in np.flatnonzero(problem != "")])
        s_full = np.full(n, np.nan)
        if dropped.any():
            s_full, _ = solve_slip(dict(c, **full), vmag, target)

        alpha, beta, z, _ = steady_state(c, s0, vmag)
        i0 = v0 / z
        ep0, psik0 = alpha * i0, beta * i0
        epp0 = c["k5"] * ep0 + c["k4"] * psik0
        w0 = 1.0 - s0
        te0 = np.real(epp0 * np.conj(i0))
        torque, torque_notes = cls.torque_constants(p, w0, te0)
        p_out = dict(c, **torque, ti_s=p["ti"] / site.f_nom, tb_s=p["tb"] / site.f_nom,
                     y_norton=sm / (p["ra"] + 1j * c["lpp"]))
        x = {"epr": ep0.real, "epi": ep0.imag, "psir": psik0.real, "psii": psik0.imag,
             "w": w0}
        flags = {"t_low": np.zeros(n), "picked": np.zeros(n), "t_brk": np.zeros(n),
                 "status": np.ones(n)}
        s_drawn = sm * v0 * np.conj(i0)
        notes = _report(cls.name, p, site, sm, s0, s_drawn, dropped, c, full, s_full, sat_on)
        notes += [f"{site.label(k)}: {text}" for k, text in torque_notes]
        return Initial(p_out, x, {"s0": s_drawn}, flags, tuple(notes))

    # ------------------------------------------------------------------ #
    # Run time (jnp, elementwise over units)
    # ------------------------------------------------------------------ #

    @classmethod
    def emfs(cls, p: Params, x: States):
        """(E', ψk, E'') network frame, complex (n,)."""
        ep = x["epr"] + 1j * x["epi"]
        psik = x["psir"] + 1j * x["psii"]
        return ep, psik, p["k5"] * ep + p["k4"] * psik

    @classmethod
    def stator_current(cls, p: Params, epp: Array, v: Array) -> Array:
        """Current drawn, p.u. on Sm: (V − E'')/(RA + jL'')."""
        return (v - epp) / (p["ra"] + 1j * p["lpp"])

    @classmethod
    def current(cls, p: Params, x: States, z: States, v: Array) -> Array:
        """(n,) complex current drawn at bus voltage v, p.u. system base (0 once tripped)."""
        _, _, epp = cls.emfs(p, x)
        return z["status"] * p["sm"] * cls.stator_current(p, epp, v)

    @classmethod
    def rates(cls, p: Params, x: States, ports: LoadPorts) -> tuple[None, States]:
        """(None, d/dt of E', ψk (p.u./s) and ω (p.u./s)) at bus voltage ports.v (spec §4);
        0 once tripped (flag `status`)."""
        v = ports.v
        ep, psik, epp = cls.emfs(p, x)
        i = cls.stator_current(p, epp, v)
        slip = 1.0 - x["w"]
        delta = ep - psik + 1j * (p["lp"] - p["ll"]) * i
        tpp0 = safe(p["tpp0"])
        dpsik = jnp.where(p["double"] > 0,
                          (delta - 1j * p["omega_b"] * slip * tpp0 * psik) / tpp0, 0.0)
        se = quadratic_saturation(jnp.abs(epp), p["sat_a"], p["sat_b"])
        dep = (-ep + (p["ls"] - p["lp"]) * (1j * i - p["k3"] * delta) - se * epp
               - 1j * p["omega_b"] * slip * p["tp0"] * ep) / p["tp0"]
        te = jnp.real(epp * jnp.conj(i))
        dw = (te - cls.load_torque(p, x["w"])) / (2.0 * p["h"])
        dw = jnp.where(x["w"] <= 0.0, jnp.maximum(dw, 0.0), dw)
        on = ports.flags["status"]
        return None, {"epr": on * jnp.real(dep), "epi": on * jnp.imag(dep),
                      "psir": on * jnp.real(dpsik), "psii": on * jnp.imag(dpsik), "w": on * dw}

    @classmethod
    def stiff_rates(cls, p: Params, x: States, z: States) -> dict[tuple[str, str], Array]:
        """λ = ∂(dE'/dt)/∂E' and ∂(dψk/dt)/∂ψk at a fixed bus voltage (spec §4), complex
        (n,), 1/s: the stator's short-circuit decay and the slip rotation −j·ωb·s, which an
        explicit step cannot follow once a motor stalls (|ωb·s| ≈ 377 1/s). Saturation is
        frozen at the step's start; ψk has none without a second cage."""
        _, _, epp = cls.emfs(p, x)
        y = 1.0 / (p["ra"] + 1j * p["lpp"])
        rotation = -1j * p["omega_b"] * (1.0 - x["w"])
        se = quadratic_saturation(jnp.abs(epp), p["sat_a"], p["sat_b"])
        d_delta = 1.0 - 1j * (p["lp"] - p["ll"]) * p["k5"] * y  # ∂Δ/∂E'
        lam_ep = (-1.0 + (p["ls"] - p["lp"]) * (-1j * p["k5"] * y - p["k3"] * d_delta)
                  - se * p["k5"]) / p["tp0"] + rotation
        lam_psi = jnp.where(p["double"] > 0, (-1.0 - 1j * (p["lp"] - p["ll"]) * p["k4"] * y)
                            / safe(p["tpp0"]) + rotation, 0.0)
        return {("epr", "epi"): lam_ep, ("psir", "psii"): lam_psi}

    @classmethod
    def implicit_blocks(cls) -> tuple[tuple[str, ...], ...]:
        """The motor's E', ψk and speed: its electromechanical mode (E' against ω) is the
        one `stiff_rates` leaves to the explicit step."""
        return (MOTOR_STATES,)

    @classmethod
    def update(cls, p: Params, x: States, z: States, v: Array, v_old: Array, dt: float) -> States:
        """Under-voltage trip after an accepted step of dt s at bus voltage v (spec §7)."""
        armed = (p["vi"] > 0) & (z["picked"] < 0.5) & (z["status"] > 0.5)
        t_low = jnp.where(armed & (jnp.abs(v) < p["vi"]), z["t_low"] + dt, 0.0 * z["t_low"])
        pickup = armed & (jnp.abs(v) < p["vi"]) & timer_fires(t_low, p["ti_s"], dt)
        t_brk = jnp.where(z["picked"] > 0.5, z["t_brk"] + dt, 0.0 * z["t_brk"])
        picked = jnp.where(pickup, 1.0, z["picked"])
        trip = (picked > 0.5) & timer_fires(t_brk, p["tb_s"], dt)
        return {"t_low": t_low, "picked": picked, "t_brk": t_brk,
                "status": jnp.where(trip, 0.0, z["status"])}

    @classmethod
    def electrical_torque(cls, p: Params, x: States, v: Array) -> Array:
        """Air-gap torque Te = Re(E''·conj(I)), p.u. on Sm (diagnostics)."""
        _, _, epp = cls.emfs(p, x)
        return jnp.real(epp * jnp.conj(cls.stator_current(p, epp, v)))


class Cim6bl(Cim5bl):
    """CIM6BL: CIM5BL with the load torque T0·(Aω² + Bω + C0 + Dω^E) (spec §1.2).

    D is a coefficient here (an exponent in CIM5BL); C0 is recomputed so the bracket is 1
    at the initial speed, and T0 = Te0.
    """

    name = "CIM6BL"
    cons = _CIRCUIT + (
        Con("a", "-", "load-torque coefficient A of ω²"),
        Con("b", "-", "load-torque coefficient B of ω"),
        Con("d", "-", "load-torque coefficient D of ω^E"),
        Con("e", "-", "load-torque exponent E"),
        Con("c0", "-", "load-torque constant C0 (recomputed at initialisation)"),
        _TNOM)

    @classmethod
    def torque_constants(cls, p, w0, te0):
        c0 = 1.0 - p["a"] * w0 ** 2 - p["b"] * w0 - p["d"] * w0 ** p["e"]
        notes = [(k, f"CIM6BL C0 = {p['c0'][k]:g} in the file, {c0[k]:.6g} computed so that "
                     f"TL(ω0) = Te0 (file value not used)")
                 for k in np.flatnonzero(np.abs(c0 - p["c0"]) > C0_REPORT_TOL)]
        return {"t0": te0, "c0": c0}, notes

    @classmethod
    def load_torque(cls, p, w):
        """T0·(Aω² + Bω + C0 + D·ω^E), p.u. on Sm."""
        power = p["d"] * jnp.maximum(w, W_TORQUE_MIN) ** p["e"]
        return p["t0"] * (p["a"] * w ** 2 + p["b"] * w + p["c0"] + power)


INDUCTION_MOTORS = {m.name: m for m in (Cim5bl, Cim6bl)}


# --------------------------------------------------------------------------- #
# Circuit and steady state (host, NumPy float64)
# --------------------------------------------------------------------------- #

def circuit_impedance(p: dict, s) -> np.ndarray:
    """Exact type-1 double-cage circuit impedance Z(s), p.u. on Sm (spec §3.1).

    Z(s) = RA + jXA + [jXM ∥ (R1/s + jX1) ∥ (R2/s + jX2)], the second branch absent for a
    single cage (R2 = 0 or X2 = 0). p: CON arrays; s: slips > 0 broadcasting against them.
    """
    s = np.asarray(s, dtype=float)
    double = (p["r2"] > 0) & (p["x2"] > 0)
    y = 1.0 / (1j * p["xm"]) + 1.0 / (p["r1"] / s + 1j * p["x1"])
    y2 = 1.0 / (np.where(double, p["r2"], 1.0) / s + 1j * np.where(double, p["x2"], 1.0))
    return p["ra"] + 1j * p["xa"] + 1.0 / (y + np.where(double, y2, 0.0))


def motor_constants(p: dict, omega_b, stiff_below: float) -> dict[str, np.ndarray]:
    """Ls, Lp, Lpp, Ll (p.u.), T'0, T''0 (s), k3, k4, k5 and `double` (spec §3.1, §3.2, §4).

    A second cage with T''0 < stiff_below (s) is dropped (Lpp := Lp, double = 0).
    """
    xa, xm, x1, x2 = p["xa"], p["xm"], p["x1"], p["x2"]
    r1, r2 = p["r1"], p["r2"]
    with np.errstate(divide="ignore", invalid="ignore"):
        cage2 = (r2 > 0) & (x2 > 0)
        type2 = p["it"] == 2
        x1m = xm * x1 / (xm + x1)
        lp = np.where(type2, xa + xm * (x1 + x2) / (xm + x1 + x2), xa + x1m)
        lpp = np.where(type2, xa + x1m, xa + 1.0 / (1.0 / xm + 1.0 / x1 + 1.0 / x2))
        tp0 = np.where(type2, (xm + x1 + x2) / (omega_b * r2), (x1 + xm) / (omega_b * r1))
        tpp0 = np.where(type2, x2 * (x1 + xm) / (x2 + x1 + xm) / (omega_b * r1),
                        (x2 + x1m) / (omega_b * r2))
        tpp0 = np.where(cage2, tpp0, 0.0)
    return transient_constants(xa + xm, lp, lpp, xa, tp0, tpp0, cage2, stiff_below)


def motorw_circuit(ls, lp, lpp, tp0, tpp0, ll, omega_b) -> dict[str, np.ndarray]:
    """The type-1 double-cage circuit (xa = Ll, xm, r1, x1, r2, x2; p.u., arrays (n,)) whose
    impedance equals the WECC `motorw` form's at every slip (spec §6):

        Z(s) = Rs + jL'' + j(L' − L'')/(1 + jωb·s·T''0) + j(Ls − L')/(1 + jωb·s·T'0).

    With p = jωb·s, the rotor admittance 1/(Z − Rs − jLl) = 1/Xm + Σ_i (1/X_i)·p/(p + a_i)
    (a_i = ωb·R_i/X_i) is the partial-fraction form of D(p)/N(p), D = (1 + pT'0)(1 + pT''0),
    N = (L'' − Ll)·D + (Ls − L')(1 + pT''0) + (L' − L'')(1 + pT'0); its poles −a_i (the
    roots of N, negative reals) and residues give the cages, the slower one as cage 1. The
    §4 equations with this circuit's constants (`motor_constants`) have the same transfer
    function as the motorw form, so, the slip rotation acting alike on every rotor state,
    the same dynamics for any speed; Ll (< L'') only picks the realisation. Needs
    Ll < L'' < L' < Ls and T'0, T''0 > 0.
    """
    t1, t2 = np.asarray(tp0, float), np.asarray(tpp0, float)
    d1, d2, c0 = ls - lp, lp - lpp, lpp - ll
    quad = c0 * t1 * t2
    lin = c0 * (t1 + t2) + d1 * t2 + d2 * t1
    const = c0 + d1 + d2
    root = np.sqrt(lin ** 2 - 4.0 * quad * const)
    cages = {}
    for name, a in (("1", (lin - root) / (2.0 * quad)), ("2", (lin + root) / (2.0 * quad))):
        d_at = (1.0 - a * t1) * (1.0 - a * t2)  # D(−a)
        slope = -2.0 * quad * a + lin  # N'(−a)
        x = -a * slope / d_at  # 1/residue
        cages.update({f"x{name}": x, f"r{name}": a * x / omega_b})
    return dict(xa=ll, xm=ls - ll, it=np.ones_like(t1), **cages)


def transient_constants(ls, lp, lpp, ll, tp0, tpp0, cage2, stiff_below: float):
    """The §4 constants from reactances Ls, L', L'', Ll (p.u.) and T'0, T''0 (s), arrays (n,).

    cage2 (n,) bool: a second cage is given. It is dropped (L'' := L', k3 = k4 = 0, k5 = 1,
    double = 0) when T''0 < stiff_below (s), the stiff-stage rule of spec §6.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        double = cage2 & (tpp0 >= stiff_below)
        lpp = np.where(double, lpp, lp)
        span = np.where(double, lp - ll, 1.0)
        k3 = np.where(double, (lp - lpp) / span ** 2, 0.0)
        k4 = np.where(double, (lp - lpp) / span, 0.0)
        k5 = np.where(double, (lpp - ll) / span, 1.0)
    return {"ls": ls, "lp": lp, "lpp": lpp, "ll": ll, "tp0": tp0,
            "tpp0": np.where(double, tpp0, 0.0), "k3": k3, "k4": k4, "k5": k5,
            "double": double.astype(float)}


def steady_impedance(c: dict, s, se=0.0):
    """(α, β, Z): the steady state of the §4 equations at slip s with saturation factor se.

    E' = α·I, ψk = β·I and V = Z·I (I drawn, p.u. on Sm); for a type-1 motor without
    saturation Z equals `circuit_impedance` at every slip. c: constants of `motor_constants`
    plus ra and omega_b; arrays broadcast against s.
    """
    a1 = c["omega_b"] * s * c["tp0"]
    a2 = c["omega_b"] * s * c["tpp0"]
    big_l, big_m = c["lp"] - c["ll"], c["ls"] - c["lp"]
    g = 1.0 / (1.0 + 1j * a2)
    den = 1.0 + 1j * a1 + big_m * c["k3"] * 1j * a2 * g + se * (c["k5"] + c["k4"] * g)
    num = 1j * big_m + big_m * c["k3"] * a2 * g * big_l - se * c["k4"] * g * 1j * big_l
    alpha = num / den
    beta = g * (alpha + 1j * big_l)
    return alpha, beta, c["ra"] + 1j * c["lpp"] + c["k5"] * alpha + c["k4"] * beta


def steady_state(c: dict, s, vmag):
    """(α, β, Z, Se) at slip s and terminal voltage magnitude vmag, saturation included.

    Se solves Se = Se(|E''(Se)|); |E''| falls as Se rises, so the root is unique in
    [0, Se(|E''(0)|)] and is found by bisection (a plain fixed-point sweep can stall when
    the curve is steep).
    """
    def residual(se):
        alpha, beta, z = steady_impedance(c, s, se)
        epp = np.abs(c["k5"] * alpha + c["k4"] * beta) * vmag / np.abs(z)
        return quadratic_saturation(epp, c["sat_a"], c["sat_b"], xp=np) - se

    if not np.any(c["sat_b"] > 0):
        return (*steady_impedance(c, s, 0.0), 0.0)
    lo = np.zeros(np.broadcast(s, vmag, c["sat_b"]).shape)
    hi = residual(lo)
    for _ in range(SAT_BISECTIONS):
        mid = 0.5 * (lo + hi)
        up = residual(mid) > 0
        lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
    se = 0.5 * (lo + hi)
    return (*steady_impedance(c, s, se), se)


def _torque_and_power(c: dict, s, vmag):
    """(Te, P) at slip s: air-gap torque and input power, p.u. on Sm."""
    alpha, beta, z, _ = steady_state(c, s, vmag)
    i2 = (vmag / np.abs(z)) ** 2
    return i2 * np.real(c["k5"] * alpha + c["k4"] * beta), i2 * np.real(z)


def solve_slip(c: dict, vmag: np.ndarray, target: np.ndarray):
    """(s0 (n,), problem (n,) str): the low-slip root of P(s) = target (spec §5).

    Scans log-spaced slips for the first maximum of the air-gap torque (breakdown),
    refines it by golden section, then bisects P(s) = target on [SLIP_MIN, s_breakdown].
    problem is "" where a root exists, else why not (s0 is then nan).
    """
    col = {k: (v[:, None] if np.ndim(v) else v) for k, v in c.items()}
    grid = np.logspace(np.log10(SLIP_MIN), 0.0, SLIP_GRID)
    te, _ = _torque_and_power(col, grid[None, :], vmag[:, None])
    falling = np.diff(te, axis=1) < 0
    first = np.where(falling.any(axis=1), falling.argmax(axis=1), SLIP_GRID - 1)
    lo = grid[np.maximum(first - 1, 0)]
    hi = grid[np.minimum(first + 1, SLIP_GRID - 1)]
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    for _ in range(GOLDEN_STEPS):
        m1, m2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        left = _torque_and_power(c, m1, vmag)[0] > _torque_and_power(c, m2, vmag)[0]
        lo, hi = np.where(left, lo, m1), np.where(left, m2, hi)
    s_break = 0.5 * (lo + hi)
    p_break = _torque_and_power(c, s_break, vmag)[1]
    p_min = _torque_and_power(c, np.full_like(vmag, SLIP_MIN), vmag)[1]
    problem = np.full(vmag.shape, "", dtype=object)
    problem[target > p_break] = "P/Sm exceeds the power at breakdown torque"
    problem[target <= p_min] = "P/Sm is below the no-load loss"
    ok = problem == ""
    lo, hi = np.full_like(vmag, SLIP_MIN), np.where(ok, s_break, 1.0)
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        below = _torque_and_power(c, mid, vmag)[1] < target
        halved = np.where(below, mid, lo), np.where(below, hi, mid)
        if np.array_equal(halved[0], lo) and np.array_equal(halved[1], hi):
            break  # a fixed point (brackets at float resolution): the rest would repeat it
        lo, hi = halved
    for k in np.flatnonzero(~ok):
        problem[k] = (f"{problem[k]} (P/Sm = {target[k]:.4g}, at breakdown "
                      f"{p_break[k]:.4g}, no-load {p_min[k]:.3g})")
    return np.where(ok, 0.5 * (lo + hi), np.nan), problem


def _raise_all(messages: list[str]) -> None:
    """One ModelError listing every unit's problem, if there is any."""
    if messages:
        raise ModelError("\n".join(messages))


def _saturated(e1, se1, e2, se2):
    """Saturation in use: all four points given (spec §3.3; otherwise off, reported)."""
    e1, se1, e2, se2 = (np.asarray(v) for v in (e1, se1, e2, se2))
    return (e1 > 0) & (se1 > 0) & (e2 > 0) & (se2 > 0)


def _report(name, p, site, sm, s0, s_drawn, dropped, c, full, s_full, sat_on) -> list[str]:
    """Load-report lines: one per unit, then one per substitution (host)."""
    notes = []
    for k in range(s0.shape[0]):
        label = site.label(k)
        base = (f"MBASE = {p['mbase'][k]:g} MVA" if p["mbase"][k] > 0 else
                f"MBASE = 0: Sm = PMULT × P = {p['pmult'][k]:g} × "
                f"{site.record_p[k] * site.sbase:.3f} MW")
        cage = ("double cage" if c["double"][k] > 0 else
                "single cage" if not dropped[k] else "second cage dropped")
        notes.append(f"{label}: {name} motor {s_drawn[k].real * site.sbase:.3f} MW, "
                     f"Sm = {sm[k] * site.sbase:.3f} MVA ({base}), slip s0 = {s0[k]:.6f}, "
                     f"Q drawn = {s_drawn[k].imag * site.sbase:.3f} Mvar, {cage}, type "
                     f"{int(p['it'][k])}")
        if dropped[k]:
            notes.append(f"{label}: T''0 = {1e3 * full['tpp0'][k]:.2f} ms < stiff_below: "
                         f"second cage dropped (L'' := L' = {c['lp'][k]:.4f}); slip "
                         f"{s0[k]:.6f} instead of {s_full[k]:.6f} with both cages")
        if p["it"][k] == 2:
            notes.append(f"{label}: IT = 2: deep-bar constants of spec §3.2 [unverified]; they "
                         f"approximate the ladder circuit only for R1 >> R2 (R1 = "
                         f"{p['r1'][k]:g}, R2 = {p['r2'][k]:g})")
        given = [p[n][k] > 0 for n in ("e1", "se1", "e2", "se2")]
        if any(given) and not sat_on[k]:
            notes.append(f"{label}: saturation data E1 = {p['e1'][k]:g}, SE(E1) = "
                         f"{p['se1'][k]:g}, E2 = {p['e2'][k]:g}, SE(E2) = {p['se2'][k]:g} "
                         "incomplete: no saturation")
    return notes
