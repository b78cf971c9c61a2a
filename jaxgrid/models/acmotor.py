"""ACMTBLU1: the performance-based single-phase air-conditioner motor (WECC motor D, ld1pac).

Equations, CON order and defaults follow `shared/specs/acmtblu1.md`. The model is algebraic
in the terminal voltage V (running-1, running-2 and stalled P/Q characteristics, §5); all
its dynamics are per-step logic (§6): measured voltage and frequency lags, winding
temperatures, stall and restart timers, contactor drop-out and reclose, two under-voltage
trip stages and the thermal trip ramp. They are `flags` of the `LoadModel` interface,
updated once per accepted step from that step's network voltage; the lags and temperatures
use the exact discretisation x += (1 − exp(−dt/T))·(u − x), so T = 0 means "no lag".

The bus frequency input is the filtered derivative of the bus voltage angle,
f = 1 + Δθ/(ω0·dt) between accepted steps, held while |V| < 0.1 p.u. (the angle of a
collapsed voltage is meaningless); switching instants give short spikes, as in PSS/E.

Switches where the reference simulators disagree (`MotorOptions`, each [choice] of the spec):
  share_mode: how much load a motor represents (§3): "gridpack" (default: the fraction of
    the RAW load record given by a 36th CON, GridPACK's extension, else 0.43, as GridPACK,
    the simulator of the PARS study, reads these records; docs/models.md measures it),
    "psse_load_record" (the whole load record the model is attached to),
    "interpss_bus_total" (CompLF × the bus's total load, what the RLGC-era simulator
    InterPSS did), "fraction:x" (x of the load record).
  heating: which parts heat their windings (§6.1): "stalled" (default, the PSS/E and WECC
    description: a stalled part heats with I = V·|Ys|, a running part adds no heat and
    cools from its initial temperature I0²·Rstall) or "gridpack" (GridPACK as published: a
    running part A heats with the running power of the previous step over the present
    voltage, which next to a bolted fault (V → 0) heats it by orders of magnitude in one
    step, and a running part B adds no heat). Either way the thermal trip ramp acts only
    on a stalled part, as in both references.
  vx_rule: the stall-jump voltage Vx (§4): "reference_running1" (default: the running-1
    curve crossing the stalled power, as InterPSS and GridPACK, which reproduces the
    original study) or "spec_running2" (the WECC text's running-2 crossing).
  curve_offsets: "v0" (default; InterPSS/GridPACK: the curves pass through the initial
    power at V0) or "1pu" (offsets referred to V = 1, as transcribed from the WECC text).
  restall_b: False (default; the references: one stall timer, parts A and B stall
    together and a restarted B never stalls again) or True (per-part timers).
  contactor: "memory" (default, §6.4: the deepest dip decides the open share, which
    recloses linearly between Vc2on and Vc1on) or "gridpack" (GridPACK's code: inside the
    drop-out band the open share follows the present measured voltage, so contactors also
    reclose along the drop-out line while the voltage rises through it, and fully once it
    leaves the band above Vc1off).
Other choices: timers fire at ≥ T − 0.01·dt, not § 6.7's T − 1e-9 s, which float32
round-off of the summed steps defeats (`base.timer_fires`); CompPF = 0 is rejected (a power factor is needed); Vx is floored at
`VX_FLOOR` p.u. so a running motor's current stays bounded; the current is computed as
an equivalent admittance conj(S)/|V|², which is exact and safe at V → 0.

Gradient surrogate (for model-predictive control, `baselines.mpc`): the stall, the stall
jump at Vx and the restart are switches with zero gradient. Parameters
`stall_surrogate_v` (p.u.) and `stall_surrogate_t` (s), 0 in a compiled model, give them
the gradient of a sigmoid of that width in the voltage margin and the timer margin
(`base.surrogate_gradient`); the simulated values stay bitwise those of the exact model.
UV trips, contactors and thermal tripping keep their exact (zero) gradient.
"""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrid import vecmath
from jaxgrid.models.base import (Array, Con, Initial, LoadModel, LoadSite, ModelError, Params,
                                 Sentinel, States, device_label, surrogate_gradient,
                                 timer_fires)
from jaxgrid.models.options import MotorOptions

VX_FLOOR = 0.3  # p.u.: lowest stall-jump voltage (spec §7 guard)
GRIDPACK_SHARE = 0.43  # GridPACK's A/C motor fraction of its load record when no CON(36)
VX_SCAN_FROM = 0.4  # p.u.: where the Vx search starts (spec §4)
V_ANGLE_MIN = 0.1  # p.u.: below it the bus frequency measurement holds
NO_DIP = 10.0  # p.u.: contactor memory "no dip seen" (a finite +inf)


def _t(name, info, sentinel=None):
    return Con(name, "s", info, 0.0, 1e4, sentinel=sentinel)


def _v(name, info, sentinel=None):
    return Con(name, "p.u.", info, 0.0, 2.0, sentinel=sentinel)


NO_RESTART = Sentinel("part B never restarts")


def _f(name, info):
    return Con(name, "-", info, 0.0, 1.0)


def _k(name, info):
    return Con(name, "p.u.", info, -100.0, 100.0)


class Acmtblu1(LoadModel):
    """ACMTBLU1 (USRLOD, 35 CONs), one row per motor; powers in p.u. on the motor base Sm."""

    name = "ACMTBLU1"
    cons = (
        _t("tstall", "time below Vstall before the motors stall",
           Sentinel("the motors never stall")),
        _t("trst", "time above Vrst before part B restarts", NO_RESTART),
        _t("tv", "voltage measurement lag"),
        _t("tf", "frequency measurement lag"),
        Con("complf", "p.u.", "compressor load factor P/Sm (<= 0 means 1)", -10.0, 10.0),
        Con("comppf", "-", "compressor power factor (lagging)", 0.0, 1.0, positive=True),
        _v("vstall", "stall voltage at rated load"),
        Con("rstall", "p.u.", "stalled resistance, motor base", 0.0, 100.0),
        Con("xstall", "p.u.", "stalled reactance, motor base", 0.0, 100.0),
        Con("lfadj", "-", "load sensitivity of Vstall and Vbrk", -10.0, 10.0),
        _k("kp1", "running-1 P coefficient"), _k("np1", "running-1 P exponent"),
        _k("kq1", "running-1 Q coefficient"), _k("nq1", "running-1 Q exponent"),
        _k("kp2", "running-2 P coefficient"), _k("np2", "running-2 P exponent"),
        _k("kq2", "running-2 Q coefficient"), _k("nq2", "running-2 Q exponent"),
        _v("vbrk", "breakdown voltage between running regions 1 and 2"),
        _f("frst", "fraction of motors that can restart (part B)"),
        _v("vrst", "restart voltage", NO_RESTART),
        _k("cmpkpf", "P frequency sensitivity, p.u. P / p.u. f"),
        _k("cmpkqf", "Q frequency sensitivity, p.u. Q / p.u. f"),
        _v("vc1off", "contactors start to drop out below"),
        _v("vc2off", "all contactors out below"),
        _v("vc1on", "all dropped contactors back in above"),
        _v("vc2on", "dropped contactors start to reclose above"),
        _t("tth", "winding thermal time constant"),
        Con("th1t", "p.u.", "temperature where thermal tripping starts", -10.0, 100.0,
            sentinel=Sentinel("thermal tripping never starts")),
        Con("th2t", "p.u.", "temperature where all motors are tripped", -10.0, 100.0,
            sentinel=Sentinel("thermal tripping never completes (its ramp from TH1T ends "
                              "there)")),
        _f("fuvr", "fraction of motors with under-voltage relays"),
        _v("uvtr1", "UV relay stage-1 pickup"),
        _t("ttr1", "UV stage-1 time", Sentinel("UV relay stage 1 never trips")),
        _v("uvtr2", "UV relay stage-2 pickup"),
        _t("ttr2", "UV stage-2 time", Sentinel("UV relay stage 2 never trips")),
    )
    states = ()
    flags = ("vm", "fm", "theta_a", "theta_b", "run_a", "run_b", "ts_a", "ts_b", "tr_b",
             "tu1", "tu2", "kuv", "vc_min", "kcon", "fth_a", "fth_b")
    # the winding temperatures start at I0²·Rstall (as GridPACK's) and, with heating
    # "stalled", cool while the motor runs: not a rest value
    relaxing = ("theta_a", "theta_b")

    @classmethod
    def read(cls, records):
        """CON arrays (module docstring), with "record_share": GridPACK's optional 36th CON,
        the motor's fraction of its load record (0, or a record of 35 CONs: not given)."""
        n = len(cls.cons)
        extra = [r.cons[n] if len(r.cons) == n + 1 else 0.0 for r in records]
        for r, share in zip(records, extra):
            if not 0.0 <= share <= 1.0:
                raise ModelError(f"{device_label(r)}: CON(36) (GridPACK's A/C motor share of the "
                                 f"load record) = {share:g}: allowed [0, 1] (0: GridPACK's default)")
        p = super().read([dataclasses.replace(r, cons=r.cons[:n]) if len(r.cons) == n + 1
                          else r for r in records])
        return dict(p, record_share=np.asarray(extra))

    @classmethod
    def check_combination(cls, p: dict[str, float]) -> str | None:
        if p["rstall"] == 0 and p["xstall"] == 0:
            return "RSTALL = XSTALL = 0: the stalled admittance would be infinite"
        return None

    # ------------------------------------------------------------------ #
    # Initialisation (host, NumPy float64)
    # ------------------------------------------------------------------ #

    @classmethod
    def init(cls, p: Params, site: LoadSite) -> Initial:
        """At site, with the readings site.motors (share mode, Vx rule, curve offsets)."""
        options = site.motors
        p = {k: np.asarray(v, dtype=float) for k, v in p.items()}
        notes = []
        raw_lf = p["complf"]
        lf = np.where(p["complf"] > 0, p["complf"], 1.0)
        adjust = 1.0 + p["lfadj"] * (lf - 1.0)
        vstall, vbrk = p["vstall"] * adjust, p["vbrk"] * adjust
        z2 = p["rstall"] ** 2 + p["xstall"] ** 2
        gs, bs = p["rstall"] / z2, p["xstall"] / z2
        motor_p = _motor_share(site, dict(p, complf=lf), options)
        sm = motor_p / lf  # motor base / system base
        v0 = np.abs(site.v0)
        q_init = lf * np.tan(np.arccos(p["comppf"]))
        v_ref = v0 if options.curve_offsets == "v0" else np.ones_like(v0)
        p.update(complf=lf, vstall_adj=vstall, vbrk_adj=vbrk, gs=gs, bs=bs, sm=sm,
                 omega0=np.full_like(v0, 2 * np.pi * site.f_nom),
                 restall=np.full_like(v0, float(options.restall_b)),
                 contactor_gridpack=np.full_like(v0, float(options.contactor == "gridpack")),
                 heat_gridpack=np.full_like(v0, float(options.heating == "gridpack")),
                 stall_surrogate_v=np.zeros_like(v0), stall_surrogate_t=np.zeros_like(v0),
                 thermal_on=((p["th1t"] > 0) & (p["th2t"] > p["th1t"])).astype(float))
        p0 = lf - _running_curve(p, v_ref, "p", 0.0 * v0)
        q0 = q_init - _running_curve(p, v_ref, "q", 0.0 * v0)
        p.update(p0=p0, q0=q0)
        vx, floored = _stall_jump_voltage(p, options.vx_rule)
        p["vx"] = vx
        _fix_contactor(p, notes, site)
        p["y_norton"] = sm * (gs - 1j * bs)
        s_motor = _power(p, v0, 1.0, 0.0, np)  # motor base, all running, fm = 1
        theta0 = _heat(p, v0, 1.0, 0.0, np)  # the winding temperature at rest
        n = v0.shape[0]
        z = dict(vm=v0, fm=np.ones(n), theta_a=theta0, theta_b=theta0, run_a=np.ones(n),
                 run_b=np.ones(n), ts_a=np.zeros(n), ts_b=np.zeros(n), tr_b=np.zeros(n),
                 tu1=np.zeros(n), tu2=np.zeros(n), kuv=np.ones(n), vc_min=np.full(n, NO_DIP),
                 kcon=np.ones(n), fth_a=np.ones(n), fth_b=np.ones(n))
        for k in range(n):
            notes.append(
                f"{site.label(k)}: {motor_p[k] * site.sbase:.2f} MW motor ({options.share_mode}), "
                f"Sm = {sm[k] * site.sbase:.2f} MVA, Q = {s_motor[k].imag * sm[k] * site.sbase:.2f} "
                f"Mvar, Vstall' = {vstall[k]:.4f}, Vbrk' = {vbrk[k]:.4f}, Vx = {vx[k]:.4f} p.u. "
                f"({options.vx_rule}{', floored' if floored[k] else ''})")
            if raw_lf[k] <= 0:
                notes.append(f"{site.label(k)}: COMPLF = {raw_lf[k]:g} <= 0: taken as 1")
            if not p["thermal_on"][k]:
                notes.append(f"{site.label(k)}: TH1T = {p['th1t'][k]:g}, TH2T = {p['th2t'][k]:g}: thermal "
                             "protection disabled")
            if v0[k] < vbrk[k]:
                notes.append(f"{site.label(k)}: V0 = {v0[k]:.4f} p.u. is below Vbrk' = {vbrk[k]:.4f}: the motor "
                             "starts on its running-2 curve")
            if v0[k] < vstall[k]:
                notes.append(f"{site.label(k)}: V0 = {v0[k]:.4f} p.u. is below Vstall' = {vstall[k]:.4f}: the "
                             "motor stalls after Tstall")
        return Initial(p, {}, {"s0": s_motor * sm}, z, tuple(notes))

    # ------------------------------------------------------------------ #
    # Network injection and per-step logic (jnp)
    # ------------------------------------------------------------------ #

    @classmethod
    def current(cls, p: Params, x: States, z: States, v: Array) -> Array:
        vmag = jnp.abs(v)
        s = p["sm"] * motor_power(p, z, vmag)
        return jnp.conj(s) * v / jnp.maximum(vmag ** 2, 1e-12)

    @classmethod
    def update(cls, p: Params, x: States, z: States, v: Array, v_old: Array, dt: float) -> States:
        vmag = jnp.abs(v)
        measurable = (vmag > V_ANGLE_MIN) & (jnp.abs(v_old) > V_ANGLE_MIN)
        step = vecmath.angle(v * jnp.conj(jnp.where(measurable, v_old, v)))
        f = 1.0 + jnp.where(measurable, step, 0.0) / (p["omega0"] * dt)
        vm = _lag_step(z["vm"], vmag, p["tv"], dt)
        fm = _lag_step(z["fm"], f, p["tf"], dt)
        heat = {part: _heating(p, part, vmag, jnp.abs(v_old), z[f"run_{part}"], z["fm"] - 1.0)
                for part in "ab"}
        theta = {part: _lag_step(z[f"theta_{part}"], heat[part], p["tth"], dt) for part in "ab"}
        run_a, run_b, ts_a, ts_b, tr_b = _stall_and_restart(p, z, vmag, dt)
        stalled = {"a": run_a < 0.5, "b": run_b < 0.5}
        vc_min, kcon = _contactor(p, z["vc_min"], z["kcon"], vm)
        tu1 = jnp.where((p["fuvr"] > 0) & (vm < p["uvtr1"]), z["tu1"] + dt, 0.0)
        tu2 = jnp.where((p["fuvr"] > 0) & (vm < p["uvtr2"]), z["tu2"] + dt, 0.0)
        uv_trip = timer_fires(tu1, p["ttr1"], dt) | timer_fires(tu2, p["ttr2"], dt)
        kuv = jnp.where(uv_trip & (p["fuvr"] > 0), jnp.minimum(z["kuv"], 1.0 - p["fuvr"]),
                        z["kuv"])
        span = jnp.where(p["thermal_on"] > 0, p["th2t"] - p["th1t"], 1.0)
        fth = {part: jnp.where((p["thermal_on"] > 0) & stalled[part], jnp.minimum(
            z[f"fth_{part}"], jnp.clip((p["th2t"] - theta[part]) / span, 0.0, 1.0)),
            z[f"fth_{part}"]) for part in "ab"}
        return dict(vm=vm, fm=fm, theta_a=theta["a"], theta_b=theta["b"], run_a=run_a,
                    run_b=run_b, ts_a=ts_a, ts_b=ts_b, tr_b=tr_b, tu1=tu1, tu2=tu2, kuv=kuv,
                    vc_min=vc_min, kcon=kcon, fth_a=fth["a"], fth_b=fth["b"])


# --------------------------------------------------------------------------- #
# Characteristics (spec §5), usable with NumPy (init) and jnp (run): `xp`
# --------------------------------------------------------------------------- #

def _running_curve(p, vmag, axis: str, running2, xp=np):
    """Voltage term of the running curve for "p" or "q" (motor p.u.), region by `running2`."""
    up = xp.maximum(vmag - p["vbrk_adj"], 0.0)
    down = xp.maximum(p["vbrk_adj"] - vmag, 0.0)
    pow_ = np.power if xp is np else vecmath.power
    one = p[f"k{axis}1"] * pow_(up, p[f"n{axis}1"])
    two = p[f"k{axis}2"] * pow_(down, p[f"n{axis}2"])
    return xp.where((running2 > 0) | (vmag < p["vbrk_adj"]), two, one)


def _power(p, vmag, running, dfm, xp):
    """Complex power (motor p.u.) of a part with run flag `running` (1/0) at |V| = vmag."""
    zero = 0.0 * vmag
    p_run = (p["p0"] + _running_curve(p, vmag, "p", zero, xp)) * (1.0 + p["cmpkpf"] * dfm)
    q_run = (p["q0"] + _running_curve(p, vmag, "q", zero, xp)) * (1.0 + p["cmpkqf"] * dfm)
    s_run, s_stall = p_run + 1j * q_run, (p["gs"] + 1j * p["bs"]) * vmag ** 2
    above_vx = vmag > p["vx"]
    s = xp.where((running < 0.5) | ~above_vx, s_stall, s_run)
    if xp is np:
        return s
    # gradient only (module docstring): through the run flag and the jump at Vx
    share = (above_vx * (running - jax.lax.stop_gradient(running))
             + running * surrogate_gradient(vmag - p["vx"], p["stall_surrogate_v"]))
    return s + share * (s_run - s_stall)


def motor_power(p, z, vmag, xp=jnp):
    """Complex power (p.u. on the motor base Sm) the motor draws at |V| = vmag (n,) with
    flags z: each part's power (§5) weighted by its share and thermal fraction, times the UV
    relay and contactor fractions (§7 without shedding); xp = numpy on sampled flags."""
    dfm = z["fm"] - 1.0
    s = ((1.0 - p["frst"]) * z["fth_a"] * _power(p, vmag, z["run_a"], dfm, xp)
         + p["frst"] * z["fth_b"] * _power(p, vmag, z["run_b"], dfm, xp))
    return z["kuv"] * z["kcon"] * s


def _heat(p, vmag, running, dfm, xp=jnp):
    """I²·Rstall of one motor of a part drawing its power at |V| = vmag, motor p.u."""
    s = _power(p, vmag, running, dfm, xp)
    return (xp.abs(s) / xp.maximum(vmag, 1e-6)) ** 2 * p["rstall"]


def _heating(p, part: str, vmag, vmag_old, running, dfm_old):
    """The heat input I²·Rstall (motor p.u.) of one motor of part "a" or "b" over a step to
    |V| = vmag (module docstring, `heating`): V·|Ys| when stalled; when running, none, or
    with heating "gridpack" part A's power at the previous step's |V| = vmag_old over vmag."""
    stalled = vmag ** 2 * (p["gs"] ** 2 + p["bs"] ** 2) * p["rstall"]
    running_heat = 0.0
    if part == "a":
        s_old = _power(p, vmag_old, running, dfm_old, jnp)
        running_heat = p["heat_gridpack"] * (jnp.abs(s_old) / jnp.maximum(vmag, 1e-6)) ** 2 \
            * p["rstall"]
    return jnp.where(running > 0.5, running_heat, stalled)


def _lag_step(x, u, t, dt: float):
    """Exact step of a first-order lag of time constant t (s); t == 0 gives u."""
    return x + (1.0 - jnp.exp(-dt / jnp.maximum(t, 1e-12))) * (u - x)


def _stall_and_restart(p, z, vmag, dt: float):
    """Run flags and timers after a step (spec §6.2-6.3)."""
    width_v, width_t = p["stall_surrogate_v"], p["stall_surrogate_t"]
    low_v = surrogate_gradient(p["vstall_adj"] - vmag, width_v)  # gradient of "V < Vstall'"
    low = vmag < p["vstall_adj"]
    ts = {}
    for part in "ab":
        running = z[f"run_{part}"] > 0
        ts[part] = (jnp.where(running & low, z[f"ts_{part}"] + dt, 0.0)
                    + running * low_v * (z[f"ts_{part}"] + dt))
    stall_a = (z["run_a"] > 0) & timer_fires(ts["a"], p["tstall"], dt)
    stall_b = jnp.where(p["restall"] > 0, (z["run_b"] > 0) & timer_fires(ts["b"], p["tstall"], dt),
                        stall_a & (z["run_b"] > 0))
    late_a = surrogate_gradient(ts["a"] - p["tstall"], width_t)
    late_b = jnp.where(p["restall"] > 0, surrogate_gradient(ts["b"] - p["tstall"], width_t),
                       late_a)
    run_a = jnp.where(stall_a, 0.0, z["run_a"]) - late_a * z["run_a"]
    run_b = jnp.where(stall_b, 0.0, z["run_b"]) - late_b * z["run_b"]
    ts_a, ts_b = jnp.where(stall_a, 0.0, ts["a"]), jnp.where(stall_b, 0.0, ts["b"])
    can_restart = (p["frst"] > 0) & (run_b < 0.5)
    may_restart = can_restart & (vmag > p["vrst"])
    tr_b = (jnp.where(may_restart, z["tr_b"] + dt, 0.0)
            + can_restart * surrogate_gradient(vmag - p["vrst"], width_v) * (z["tr_b"] + dt))
    restart = may_restart & timer_fires(tr_b, p["trst"], dt)
    run_b = (jnp.where(restart, 1.0, run_b)
             + may_restart * surrogate_gradient(tr_b - p["trst"], width_t) * (1.0 - run_b))
    return run_a, run_b, ts_a, ts_b, jnp.where(restart, 0.0, tr_b)


def _contactor(p, vc_min, kcon, vm):
    """(dip memory, connected share Kcon) after a step (spec §6.4; module docstring,
    `contactor`). The memory is the deepest measured voltage of the dip ("memory") or the
    last one inside the drop-out band ("gridpack")."""
    on = p["vc1off"] > 0
    off_span = jnp.where(on, p["vc1off"] - p["vc2off"], 1.0)
    on_span = jnp.where(on, p["vc1on"] - p["vc2on"], 1.0)
    x_rec = jnp.clip((vm - p["vc2on"]) / on_span, 0.0, 1.0)
    # "memory": open what the deepest dip opened, reclose only above Vc2on
    deepest = jnp.minimum(vc_min, vm)
    f_open = jnp.clip((p["vc1off"] - deepest) / off_span, 0.0, 1.0)
    memory = jnp.where(vm > deepest, 1.0 - f_open * (1.0 - x_rec), 1.0 - f_open)
    back = (vm >= p["vc1on"]) | ~on
    memory_state = (jnp.where(back, NO_DIP, deepest), jnp.where(back, 1.0, memory))
    # "gridpack": the drop-out line follows Vm inside its band, the reclose line above Vc2on
    in_band = vm < p["vc1off"]
    last = jnp.where(in_band, vm, vc_min)
    f_trip = jnp.clip((p["vc1off"] - last) / off_span, 0.0, 1.0)
    literal = jnp.where(in_band, 1.0 - f_trip, jnp.where(
        vm >= p["vc1on"], 1.0, jnp.where(vm >= p["vc2on"], 1.0 - f_trip * (1.0 - x_rec), kcon)))
    literal_state = (last, jnp.where(on, literal, 1.0))
    gridpack = p["contactor_gridpack"] > 0
    return tuple(jnp.where(gridpack, a, b) for a, b in zip(literal_state, memory_state))


# --------------------------------------------------------------------------- #
# Host-side helpers
# --------------------------------------------------------------------------- #

def _motor_share(site: LoadSite, p, options: MotorOptions):
    """Initial motor active power (p.u. system base) per share_mode (spec §3)."""
    record_p = np.asarray(site.record_p, dtype=float)
    if options.share_mode == "interpss_bus_total":
        return p["complf"] * site.bus_p
    if options.share_mode == "psse_load_record":
        return record_p
    if options.share_mode == "gridpack":
        given = p.get("record_share", np.zeros_like(record_p))
        return np.where(given > 0, given, GRIDPACK_SHARE) * record_p
    return options.share_fraction * record_p


def _first_crossing(curve, gs, lo, hi):
    """Smallest V in [lo, hi] with curve(V) <= gs·V² (bisection, 1e-9), or nan if none."""
    gap = lambda v: gs * v ** 2 - curve(v)  # noqa: E731  increasing below Vbrk'
    a, b = np.array(lo, dtype=float), np.array(hi, dtype=float)
    found = gap(b) >= 0
    at_start = gap(a) >= 0
    for _ in range(60):
        mid = 0.5 * (a + b)
        up = gap(mid) >= 0
        a, b = np.where(up, a, mid), np.where(up, mid, b)
    return np.where(at_start, lo, np.where(found, b, np.nan))


def _stall_jump_voltage(p, rule: str):
    """(Vx (n,), floored (n,) bool): the stall-jump voltage of spec §4 and §7."""
    zero = 0.0 * p["p0"]
    lo = np.full_like(p["p0"], VX_SCAN_FROM)
    hi = np.maximum(p["vstall_adj"], lo)
    if rule == "spec_running2":
        curve = lambda v: p["p0"] + _running_curve(p, v, "p", zero + 1.0)  # noqa: E731
        vx = _first_crossing(curve, p["gs"], lo, hi)
        vx = np.where(np.isnan(vx), p["vstall_adj"], vx)
    else:
        up = lambda v: np.maximum(v - p["vbrk_adj"], 0.0)  # noqa: E731
        curve = lambda v: p["p0"] + p["kp1"] * up(v) ** p["np1"]  # noqa: E731
        vx = _first_crossing(curve, p["gs"], lo, hi)
        vx = np.where(np.isnan(vx), 0.0, np.minimum(vx, p["vstall_adj"]))
    vx = np.minimum(vx, p["vstall_adj"])
    floored = vx < VX_FLOOR
    return np.maximum(vx, VX_FLOOR), floored


def _fix_contactor(p, notes: list[str], site: LoadSite) -> None:
    """GridPACK's substitutions for inconsistent contactor voltages (spec §6.4), noted."""
    bad_off = (p["vc1off"] > 0) & (p["vc2off"] >= p["vc1off"])
    bad_on = (p["vc1off"] > 0) & (p["vc2on"] >= p["vc1on"])
    for k in np.flatnonzero(bad_off):
        notes.append(f"{site.label(k)}: VC2OFF = {p['vc2off'][k]:g} >= VC1OFF = {p['vc1off'][k]:g}: VC2OFF set to 0")
    for k in np.flatnonzero(bad_on):
        notes.append(f"{site.label(k)}: VC2ON = {p['vc2on'][k]:g} >= VC1ON = {p['vc1on'][k]:g}: "
                     f"VC2ON set to VC1ON − 0.1")
    p["vc2off"] = np.where(bad_off, 0.0, p["vc2off"])
    p["vc2on"] = np.where(bad_on, p["vc1on"] - 0.1, p["vc2on"])


LOAD_MOTORS = {"ACMTBLU1": Acmtblu1}


def motor_status(p, z):
    """(running, stalled, off) shares of each motor's initial population, arrays (..., n).

    off: tripped by thermal protection or UV relays, or dropped by contactors; a shed
    share is not counted (see GridState.load_left). Works on NumPy and jnp arrays, e.g.
    on sampled flags (n_t, n) with parameters (n,).
    """
    connected = z["kuv"] * z["kcon"]
    part_a, part_b = (1.0 - p["frst"]) * z["fth_a"], p["frst"] * z["fth_b"]
    running = connected * (part_a * z["run_a"] + part_b * z["run_b"])
    stalled = connected * (part_a * (1.0 - z["run_a"]) + part_b * (1.0 - z["run_b"]))
    return running, stalled, 1.0 - running - stalled
