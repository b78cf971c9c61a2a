"""WECC composite load CMLDBLU2 / CMLDBLU1 (PSS/E USRLOD) = CMPLDW (PSLF, PowerWorld).

Structure, CONs, bases, components, discrete logic and initialisation follow
`shared/specs/cmld.md`; motor D is the ACMTBLU1 model of `jaxgrid.models.acmotor`
(`shared/specs/acmtblu1.md`), motors A-C the induction-motor equations of
`jaxgrid.models.induction` (`shared/specs/induction-motors.md`), both imported, not copied.

Files: the CON table is `jaxgrid.models.cmld_cons`, the initialisation and network
expansion `jaxgrid.models.cmld_init`; this module holds the model and its readings.

Network (spec §1, §7). The units start from their system buses (`Cmldblu2.init`, with the
other load models); then `expand` adds, per record at system bus N (load LID), two buses
and two branches to the case (numbers, names, zones and base kV: `internal_buses`):
  * the low-side bus, number N + M·(2j + 1), name "Bus<N>_lowBus", with the shunt
    Bss + Fb·Bf (system p.u.);
  * the load bus, number N + M·(2j + 2), name "Bus<N>_loadBus" (the name the PNNL task
    files use), carrying the model;
  * the substation transformer low side -> N, reactance Xxf·Tfixhs² (system p.u.) on the
    system side of an ideal ratio Tfixls·t/Tfixhs (V_low = ratio·V_h: tap up raises V_low,
    GridPACK/InterPSS, spec §6 step 2);
  * the feeder low side -> load bus, Rfdr + jXfdr.
M is the smallest power of ten above every |RAW bus number| and j counts earlier CMLD
records at the same bus (0 for the first; later ones get "_<LID>" after the name). The
RAW load record moves to the load bus with the power the feeder delivers there, so the
expanded case is at its power-flow point with the power-flow voltages of the original
case, and every CMLD becomes an ordinary load model with one load slot at its load bus.

Components at the load bus (spec §4), one `LoadModel` unit per record:
  * motors A, B, C: states ma_epr ... mc_w, the `Cim5bl` derivative and stator current with
    the constants of the WECC motorw form (Ls, Lp, Lpp, Tpo, Tppo; induction-motors.md §6)
    through its equivalent circuit (`induction.motorw_circuit`; same stiff-stage rule:
    Tppo < MotorOptions.stiff_below drops the subtransient stage, Lpp := Lp) and the CIM5
    load torque T0·ω^Etrq; two UV trip stages with reclose (§5);
  * motor D: the whole `Acmtblu1` (init, current, update) on its own parameters `d_*`;
  * electronic load with the deepest-dip memory and partial recovery Frcel (§4);
  * static load: exponential ZIP in V/V0 with frequency terms (§4);
  * the load-end feeder compensation (1 − Fb)·Bf.
Its Norton admittance is the sum of the motors' Norton admittances, motor D's stalled
admittance, the electronic and static loads at V0 and the load-end shunt.

Choices ([choice] points and open questions of spec §8; `CompositeOptions` holds the
switches). Each is the InterPSS reading where one is known, which reproduces the study:
  1. ICONs: their meaning is unknown; they are stored (`icon1`, `icon2`) and a non-zero
     value warns (CompositeWarning); they change nothing.
  2. LTC ratio: V_low = V_h·Tfixls·t/Tfixhs (tap up raises V_low). The initial tap comes
     from the closed form of spec §6 step 1 whether or not LTC = 1; LTC = 1 itself is
     rejected (ModelError), since the direction of dynamic tap moves is unverified and
     Tdel = 30 s never acts within a 10-s FIDVR episode.
  3. Motors A-C: the motorw form of induction-motors.md §6 (the WECC/PSLF description;
     GridPACK, PowerWorld, Dynawo), integrated in the §4 states of the circuit with the same
     impedance at every slip, which makes the same dynamics (`induction.motorw_circuit`).
     Reading the data as §4 constants with Ll = 0.8·Lpp (a WECC note on PSS/E's CMLD,
     [unverified]) gives another motor once the subtransient stage is kept (PNNL motor A:
     initial slip 0.030 instead of 0.044). With the WECC data (Tppo 2-3 ms) the default
     stiff-stage rule drops that stage; on the PNNL 300-bus study keeping it changes no
     uncontrolled verdict at 1 ms (docs/models.md).
  4. Bf is solved with Bss given: the whole reactive balance at the load bus is closed by
     Bf, split Fb to the low side and 1 − Fb to the load bus (spec §6 steps 3-5, a secant
     root find; the issue asks for it). `compensation="static_q"` is InterPSS's reading
     instead: no Bf, the static load's Q takes the mismatch. Extra-var removal (`extra_var`): "load_end" (default) removes, when a
     component trips or drops out, its initial-MW share of the load-end shunt (1 − Fb)·Bf;
     "none" keeps the shunt. Bss and Fb·Bf never take part (they sit at the low-side bus);
     a third reading with them is not implemented.
  5. Frequency: the static load uses motor D's measured frequency (lag Tf on the filtered
     load-bus angle derivative, acmotor.py); motor D uses it as in ACMTBLU1.
  6. Static load exponents act on V/V0 (V0 the initial load-bus voltage).
  7. Motor D is initialised at V_L0 with `MotorOptions.curve_offsets` (default "v0",
     GridPACK/InterPSS: the curves pass through the initial power at V_L0); with "1pu" the
     difference of motor D's P at V_L0 from FmD·P_L is given to the static load (reported).
Other choices: the voltage floor (spec §6 step 6) scales the feeder impedance down in
steps of `floor_step` (InterPSS: 1 %) until |V_L| >= `v_floor` (the fewest steps, found by
bisection: `cmld_init.floor_steps`); the tap is not raised first. Every adjustment is in
the load report. Shedding (spec §9, `shedding`) is end-use by default: the load-bus slot's
connected fraction scales every component and the load-end shunt; states are untouched.
"feeder" scales the whole feeder instead (`CmldFeederShed`).
CMLDBLU1 (132 CONs) has no Frcel; it is
taken as 0 (dropped electronic load does not come back) and reported. Below
`STATIC_V_BREAK` the static load becomes a constant admittance (its value at the break),
so a collapsed voltage never asks a constant-power part for full power.
"""
from __future__ import annotations

import warnings
from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from jaxgrid.records import DyrRecord
from jaxgrid.models.acmotor import Acmtblu1
from jaxgrid.models.base import (Array, Initial, LoadModel, LoadPorts, LoadSite, ModelError,
                                 Params, States, device_label, timer_fires)
from jaxgrid.models.cmld_cons import CON_FRCEL, CONS_BLU1, MOTOR_D_NAMES, MOTORS
from jaxgrid.models.cmld_init import initialise
from jaxgrid.models.induction import MOTOR_STATES, Cim5bl
from jaxgrid.models.options import CompositeOptions
from jaxgrid.vecmath import power

STATIC_V_BREAK = 0.3  # p.u.: below it the static load is a constant admittance


class CompositeWarning(UserWarning):
    """CMLD data read with a caveat (non-zero ICONs of unknown meaning)."""


class Cmldblu2(LoadModel):
    """CMLDBLU2 (USRLOD, 2 ICONs, 133 CONs), one unit per record, at its load bus.

    `init` starts the units from their system-bus site; `jaxgrid.models.cmld_init.expand`
    then adds the buses and branches it found to the case. Powers in p.u. on the system base unless a motor's own base is named.

    Attributes (states, arrays (n,)): m{x}_epr, m{x}_epi, m{x}_psir, m{x}_psii, m{x}_w for
      x in a, b, c: motor x's E', ψk (network frame, p.u.) and speed (p.u.), as in Cim5bl.
    Flags (arrays (n,)): d_* motor D's flags (Acmtblu1.flags); vmin_e: electronic load's
      deepest dip since it went below Vd1 (p.u.; NO_DIP: none); on{k}{x}: motor x's stage-k
      slice connected (0/1); ttr{k}{x}, trc{k}{x}: time below Vtrk / above Vrck, s.
    """

    name = "CMLDBLU2"
    cons = CONS_BLU1 + (CON_FRCEL,)
    states = tuple(f"m{x}_{s}" for x in MOTORS for s in Cim5bl.states)
    flags = (tuple(f"d_{f}" for f in Acmtblu1.flags) + ("vmin_e",)
             + tuple(f"{f}{k}{x}" for x in MOTORS for k in "12" for f in ("on", "ttr", "trc")))
    relaxing = tuple(f"d_{f}" for f in Acmtblu1.relaxing)  # motor D's winding temperatures
    n_record_icons = 2  # ICONs written before the CONs (rec.icons)

    @classmethod
    def read(cls, records: Sequence[DyrRecord]) -> dict[str, np.ndarray]:
        """CON arrays (n,) float64 plus icon1, icon2 (CMLDBLU2; 0 for CMLDBLU1)."""
        p = super().read(records)
        icons = np.zeros((len(records), 2))
        for k, rec in enumerate(records):
            if len(rec.icons) != cls.n_record_icons:
                raise ModelError(f"{device_label(rec)}: expected {cls.n_record_icons} ICONs, "
                                 f"found {len(rec.icons)}")
            for j, value in enumerate(rec.icons):
                if not isinstance(value, int):
                    raise ModelError(f"{device_label(rec)}: ICON({j + 1}) = {value!r}: must "
                                     "be an integer")
                icons[k, j] = value
                if value != 0:
                    warnings.warn(f"{device_label(rec)}: ICON({j + 1}) = {value}: meaning "
                                  "unknown (spec cmld.md §8.1); stored, not used",
                                  CompositeWarning, stacklevel=2)
        p.update(icon1=icons[:, 0], icon2=icons[:, 1])
        return p

    @classmethod
    def init(cls, p: Params, site: LoadSite) -> Initial:
        """The units started from the system side (spec §6, `cmld_init.initialise`): site is
        the system bus and the RAW load record each substation draws. Output: s0 (drawn at
        the load bus), v_low, v_load (the internal buses' complex voltages, p.u.), arrays
        (n,). Raises ModelError naming the unit whose record draws no active power."""
        for k in np.flatnonzero(~(site.record_p > 0))[:1]:
            raise ModelError(f"{site.label(k)}: the load record draws P = "
                             f"{site.record_p[k] * site.sbase:g} MW at the power flow; the "
                             "composite load needs P > 0")
        start = initialise(p, site.record_s, site.v0, site.sbase, site.f_nom, site.composite,
                           site.motors, [site.label(k) for k in range(len(site.v0))])
        return Initial(start.params, start.states,
                       {"s0": start.s0, "v_low": start.v_low, "v_load": start.v_load},
                       start.flags, tuple(start.notes))

    @classmethod
    def check_combination(cls, p: dict[str, float]) -> str | None:
        if p["ltc"] != 0:
            return (f"CON(9) LTC = {p['ltc']:g}: the under-load tap changer is not implemented "
                    "(only LTC = 0, taps fixed at their initial value)")
        for x in MOTORS:
            if p[f"mtyp{x}"] != 3 and p[f"fm{x}"] > 0:
                return (f"MTYP{x.upper()} = {p[f'mtyp{x}']:g}: motors A-C must be three-phase "
                        "(3)")
            if not p[f"lpp{x}"] <= p[f"lp{x}"] < p[f"ls{x}"]:
                return (f"motor {x.upper()}: needs LPP <= LP < LS (LS = {p[f'ls{x}']:g}, LP = "
                        f"{p[f'lp{x}']:g}, LPP = {p[f'lpp{x}']:g})")
        if p["tmin"] > p["tmax"]:
            return f"TMIN = {p['tmin']:g} > TMAX = {p['tmax']:g}"
        if p["vd2"] >= p["vd1"]:
            return f"VD2 = {p['vd2']:g} >= VD1 = {p['vd1']:g}: the drop-out band is empty"
        if p["rfdr"] == 0 and p["xfdr"] == 0:
            return "RFDR = XFDR = 0: the feeder needs an impedance"
        return Acmtblu1.check_combination({a: p[c] for a, c in MOTOR_D_NAMES})

    # ------------------------------------------------------------------ #
    # Run time (jnp, elementwise over units)
    # ------------------------------------------------------------------ #

    @classmethod
    def current(cls, p: Params, x: States, z: States, v: Array) -> Array:
        """(n,) complex current drawn at load-bus voltage v, p.u. system base (spec §4)."""
        vmag = jnp.abs(v)
        drawn = Acmtblu1.current(_sub(p, "d_"), {}, _sub(z, "d_"), v)
        for m in MOTORS:
            pm, xm = _sub(p, f"m{m}_"), _sub(x, f"m{m}_")
            _, _, epp = Cim5bl.emfs(pm, xm)
            drawn = drawn + _motor_share(p, z, m) * pm["sm"] * Cim5bl.stator_current(pm, epp, v)
        s = _static_power(p, vmag, z["d_fm"] - 1.0) + _electronic_power(p, vmag, z["vmin_e"])
        b = p["b_le"] * jnp.where(p["extra_var"] > 0, _connected_share(p, z, vmag), 1.0)
        return drawn + jnp.conj(s) * v / jnp.maximum(vmag ** 2, 1e-12) + 1j * b * v

    @classmethod
    def rates(cls, p: Params, x: States, ports: LoadPorts) -> tuple[None, States]:
        """(None, rates of motors A-C) (Cim5bl equations; shared aggregate state, spec §5)."""
        out = {}
        for m in MOTORS:
            _, rates = Cim5bl.rates(_sub(p, f"m{m}_"), _sub(x, f"m{m}_"),
                                    LoadPorts(v=ports.v, flags={"status": 1.0}))
            out.update({f"m{m}_{k}": r for k, r in rates.items()})
        return None, out

    @classmethod
    def stiff_rates(cls, p: Params, x: States, z: States) -> dict[tuple[str, str], Array]:
        """Motors A-C's stiff E' and ψk rates (`Cim5bl.stiff_rates`)."""
        return {(f"m{m}_{re}", f"m{m}_{im}"): lam for m in MOTORS
                for (re, im), lam in Cim5bl.stiff_rates(_sub(p, f"m{m}_"), _sub(x, f"m{m}_"),
                                                        {}).items()}

    @classmethod
    def implicit_blocks(cls) -> tuple[tuple[str, ...], ...]:
        """Motors A-C's states, one block per motor (`Cim5bl.implicit_blocks`)."""
        return tuple(tuple(f"m{m}_{name}" for name in MOTOR_STATES) for m in MOTORS)

    @classmethod
    def update(cls, p: Params, x: States, z: States, v: Array, v_old: Array, dt: float) -> States:
        """Flags after an accepted step: motor D, electronic memory, UV trip/reclose (§4-5)."""
        vmag = jnp.abs(v)
        out = {f"d_{k}": f for k, f in
               Acmtblu1.update(_sub(p, "d_"), {}, _sub(z, "d_"), v, v_old, dt).items()}
        out["vmin_e"] = jnp.where(vmag < p["vd1"],
                                  jnp.minimum(z["vmin_e"], jnp.maximum(vmag, p["vd2"])),
                                  z["vmin_e"])
        for m in MOTORS:
            for k in "12":
                key = f"{k}{m}"
                on = z[f"on{key}"] > 0.5
                low = on & (vmag < p[f"vtr{key}"])
                ttr = jnp.where(low, z[f"ttr{key}"] + dt, 0.0)
                trip = low & timer_fires(ttr, p[f"ttr{key}"], dt)
                high = ~on & (vmag > p[f"vrc{key}"])
                trc = jnp.where(high, z[f"trc{key}"] + dt, 0.0)
                close = high & timer_fires(trc, p[f"trc{key}"], dt)
                out[f"on{key}"] = jnp.where(trip, 0.0, jnp.where(close, 1.0, z[f"on{key}"]))
                out[f"ttr{key}"] = jnp.where(trip, 0.0, ttr)
                out[f"trc{key}"] = jnp.where(close, 0.0, trc)
        return out


class Cmldblu1(Cmldblu2):
    """CMLDBLU1: CMLDBLU2 without ICONs and without Frcel (132 CONs; Frcel taken as 0)."""

    name = "CMLDBLU1"
    cons = CONS_BLU1
    n_record_icons = 0

    @classmethod
    def read(cls, records):
        p = super().read(records)
        p["frcel"] = np.zeros(len(records))
        return p


class CmldFeederShed(Cmldblu2):
    """CMLDBLU1/2 with feeder shedding (spec §9): a shed fraction opens that share of
    identical parallel feeders. The feeders left see the same voltages as the whole one, so
    the components are not scaled; the system bus draws left × the whole feeder's current
    ratio·(I_f + j·b_low·V_low), I_f the current into the load bus, V_low = V_L + z_f·I_f.
    The network holds the whole feeder; (1 − left) of that current is injected back at the
    system bus's load slot `p["upstream_slot"]`.
    """

    @classmethod
    def shed_current(cls, p, x, z, v, left):
        return cls.current(p, x, z, v)

    @classmethod
    def upstream_injection(cls, p, x, z, v, left):
        i_f = cls.current(p, x, z, v)
        v_low = v + (p["r_fdr"] + 1j * p["x_fdr"]) * i_f
        return (1.0 - left) * p["ratio"] * (i_f + 1j * p["b_low"] * v_low)


COMPOSITE_LOADS = {m.name: m for m in (Cmldblu2, Cmldblu1)}


def composite_records(records: Sequence[DyrRecord]) -> list[DyrRecord]:
    """The CMLDBLU2 records of `records`, then the CMLDBLU1 records, each in DYR order: the
    order of the units of the composite loads' one group."""
    return [r for name in COMPOSITE_LOADS for r in records if r.model == name]


def read_records(records: Sequence[DyrRecord]) -> dict[str, np.ndarray]:
    """CON arrays (n,) of `composite_records(records)` (not empty), each record type read by
    its own class."""
    parts = [model.read(rs) for name, model in COMPOSITE_LOADS.items()
             if (rs := [r for r in records if r.model == name])]
    return {k: np.concatenate([part[k] for part in parts]) for k in parts[0]}


def run_model(options: CompositeOptions) -> type[Cmldblu2]:
    """The class that runs every composite load unit under `options` (both record types)."""
    return CmldFeederShed if options.shedding == "feeder" else Cmldblu2


def _sub(tree: dict, prefix: str) -> dict:
    """The entries of `tree` whose key starts with prefix, with the prefix removed."""
    return {k[len(prefix):]: v for k, v in tree.items() if k.startswith(prefix)}


def _motor_share(p, z, m: str):
    """Connected share of motor m after its UV trip stages (spec §5), (n,)."""
    off = (p[f"ftr1{m}"] * (1.0 - z[f"on1{m}"]) + p[f"ftr2{m}"] * (1.0 - z[f"on2{m}"]))
    return jnp.maximum(1.0 - off, 0.0)


def _electronic_fraction(p, vmag, vmin_e):
    """Fvl (n,): connected share of the electronic load at |V| with dip memory vmin_e (§4)."""
    span = p["vd1"] - p["vd2"]
    falling = (vmag - p["vd2"]) / span
    recovering = ((vmin_e - p["vd2"]) + p["frcel"] * (vmag - vmin_e)) / span
    above = jnp.where(vmin_e >= p["vd1"], 1.0,
                      ((vmin_e - p["vd2"]) + p["frcel"] * (p["vd1"] - vmin_e)) / span)
    band = jnp.where(vmag <= vmin_e, falling, recovering)
    fvl = jnp.where(vmag < p["vd2"], 0.0, jnp.where(vmag < p["vd1"], band, above))
    return jnp.clip(fvl, 0.0, 1.0)


def _electronic_power(p, vmag, vmin_e):
    """Complex power (n,) of the electronic load, p.u. system base."""
    return p["p_el0"] * _electronic_fraction(p, vmag, vmin_e) * (1.0 + 1j * p["tan_el"])


def _static_power(p, vmag, dfm):
    """Complex power (n,) of the static load at |V| and frequency deviation dfm (§4).

    Below STATIC_V_BREAK the load is the admittance it has at the break.
    """
    vc = jnp.maximum(vmag, STATIC_V_BREAK)
    r = vc / p["v_l0"]
    shape_p = (p["p1c"] * power(r, p["p1e"]) + p["p2c"] * power(r, p["p2e"])
               + (1.0 - p["p1c"] - p["p2c"]))
    shape_q = (p["q1c"] * power(r, p["q1e"]) + p["q2c"] * power(r, p["q2e"])
               + (1.0 - p["q1c"] - p["q2c"]))
    s = (p["p_st0"] * shape_p * (1.0 + p["pfrq"] * dfm)
         + 1j * p["q_st0"] * shape_q * (1.0 + p["qfrq"] * dfm))
    return s * (vmag / vc) ** 2


def _connected_share(p, z, vmag):
    """Initial-MW-weighted connected share of the end uses (extra-var allocation, §5), (n,)."""
    d = (z["d_kuv"] * z["d_kcon"] * ((1.0 - p["d_frst"]) * z["d_fth_a"]
                                       + p["d_frst"] * z["d_fth_b"]))
    share = p["w_d"] * d + p["w_el"] * _electronic_fraction(p, vmag, z["vmin_e"]) + p["w_st"]
    for m in MOTORS:
        share = share + p[f"w_{m}"] * _motor_share(p, z, m)
    return share
