"""WECC composite load CMLDBLU2 / CMLDBLU1 (PSS/E USRLOD) = CMPLDW (PSLF, PowerWorld).

Structure, CONs, bases, components, discrete logic and initialisation follow
`shared/specs/cmld.md`; motor D is the ACMTBLU1 model of `jaxgrid.models.acmotor`
(`shared/specs/acmtblu1.md`), motors A-C the induction-motor equations of
`jaxgrid.models.induction` (`shared/specs/induction-motors.md`), both imported, not copied.

Network (spec §1, §7). At compile time `expand` adds, per record at system bus N (load
LID), two buses and two branches to the case (numbers, names, zones and base kV:
`internal_buses`):
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
    constants from Ls, Lp, Lpp, Tpo, Tppo through `induction.transient_constants` (same
    stiff-stage rule: Tppo < MotorOptions.stiff_below drops the subtransient stage, Lpp :=
    Lp) and the CIM5 load torque T0·ω^Etrq; two UV trip stages with reclose (§5);
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
  3. Motors A-C: the PSS/E-structured form (induction-motors.md §4) with Ll = 0.8·Lpp
     (the WECC note on PSS/E's CMLD). With the WECC data (Tppo 2-3 ms) the stiff-stage rule
     drops the subtransient stage, and then the §4 form and the motorw form of §6 are the
     same third-order model, so the choice does not change results.
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
steps of `floor_step` (InterPSS: 1 %) until |V_L| >= `v_floor`; the tap is not raised
first. Every adjustment is in the load report. Shedding (spec §9, `shedding`) is end-use
by default: the load-bus slot's connected fraction scales every component and the load-end
shunt; states are untouched. "feeder" scales the whole feeder instead (`CmldFeederShed`).
CMLDBLU1 (132 CONs) has no Frcel; it is
taken as 0 (dropped electronic load does not come back) and reported. Below
`STATIC_V_BREAK` the static load becomes a constant admittance (its value at the break),
so a collapsed voltage never asks a constant-power part for full power.
"""
from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Sequence
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from jaxgrid.case import PQ, Case, build_case, to_rows
from jaxgrid.io.dyr import DyrRecord
from jaxgrid.models.acmotor import NO_DIP, Acmtblu1, MotorOptions
from jaxgrid.models.base import (Array, Con, LoadModel, LoadSite, ModelError, Params, States,
                                 device_label, timer_fires)
from jaxgrid.models.induction import Cim5bl, solve_slip, steady_state, transient_constants
from jaxgrid.vecmath import power

MOTORS = "abc"  # the three-phase motors A, B, C
LL_OVER_LPP = 0.8  # Ll = 0.8·Lpp (WECC note on PSS/E's CMLD, spec §8 question 3)
STATIC_V_BREAK = 0.3  # p.u.: below it the static load is a constant admittance
SECANT_STEPS = 60  # iterations of the Bf root find (converges in < 10)
SECANT_TOL = 1e-13  # p.u. system base: reactive mismatch accepted at the load bus
EXTRA_VAR = ("load_end", "none")
SHEDDING = ("end_use", "feeder")
COMPENSATION = ("bf", "static_q")


class CompositeWarning(UserWarning):
    """CMLD data read with a caveat (non-zero ICONs of unknown meaning)."""


@dataclasses.dataclass(frozen=True)
class CompositeOptions:
    """Readings of the composite load where the specification leaves a choice (module doc).

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
    """

    compensation: str = "bf"
    extra_var: str = "load_end"
    v_floor: float = 0.95
    floor_step: float = 0.01
    shedding: str = "end_use"

    def __post_init__(self):
        if self.extra_var not in EXTRA_VAR:
            raise ValueError(f"extra_var = {self.extra_var!r}: allowed {', '.join(EXTRA_VAR)}")
        if self.compensation not in COMPENSATION:
            raise ValueError(f"compensation = {self.compensation!r}: allowed "
                             f"{', '.join(COMPENSATION)}")
        if self.shedding not in SHEDDING:
            raise ValueError(f"shedding = {self.shedding!r}: allowed {', '.join(SHEDDING)}")
        if not 0.0 <= self.v_floor < 1.5:
            raise ValueError(f"v_floor = {self.v_floor!r} p.u.: allowed [0, 1.5)")
        if not 0.0 < self.floor_step < 1.0:
            raise ValueError(f"floor_step = {self.floor_step!r}: allowed (0, 1)")


# --------------------------------------------------------------------------- #
# CON table (spec §2.1)
# --------------------------------------------------------------------------- #

def _pu(name, info, lo=-100.0, hi=100.0, positive=False):
    return Con(name, "p.u.", info, lo, hi, positive)


def _frac(name, info):
    return Con(name, "-", info, 0.0, 1.0)


def _motor_block(x: str) -> tuple[Con, ...]:
    """The 20 CONs of motor A, B or C (x = "a", "b", "c")."""
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
        _pu(f"vtr1{x}", f"motor {m} UV stage-1 trip voltage (0: off)", 0.0, 2.0),
        Con(f"ttr1{x}", "s", f"motor {m} UV stage-1 trip time", 0.0, 1e6),
        _frac(f"ftr1{x}", f"motor {m} fraction tripped by stage 1"),
        _pu(f"vrc1{x}", f"motor {m} stage-1 reclose voltage", 0.0, 10.0),
        Con(f"trc1{x}", "s", f"motor {m} stage-1 reclose time (~9999: none)", 0.0, 1e6),
        _pu(f"vtr2{x}", f"motor {m} UV stage-2 trip voltage (0: off)", 0.0, 2.0),
        Con(f"ttr2{x}", "s", f"motor {m} UV stage-2 trip time", 0.0, 1e6),
        _frac(f"ftr2{x}", f"motor {m} fraction tripped by stage 2"),
        _pu(f"vrc2{x}", f"motor {m} stage-2 reclose voltage", 0.0, 10.0),
        Con(f"trc2{x}", "s", f"motor {m} stage-2 reclose time (~9999: none)", 0.0, 1e6),
    )


# Motor D: the ACMTBLU1 CONs in ACMTBLU1 order, CompLF called LFmD (spec §2.1 k = 97-131).
_MOTOR_D = tuple(dataclasses.replace(c, name="lfmd") if c.name == "complf" else c
                 for c in Acmtblu1.cons)
_D_NAMES = tuple((c.name, d.name) for c, d in zip(Acmtblu1.cons, _MOTOR_D))  # (acmtblu1, cmld)

_CONS_BLU1 = (
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
) + _motor_block("a") + _motor_block("b") + _motor_block("c") + _MOTOR_D
_FRCEL = _frac("frcel", "fraction of dropped electronic load that recovers")


class Cmldblu2(LoadModel):
    """CMLDBLU2 (USRLOD, 2 ICONs, 133 CONs), one unit per record, at its load bus.

    `init` is not used: `expand` initialises the records together with the network it adds.
    Powers in p.u. on the system base unless a motor's own base is named.

    Attributes (states, arrays (n,)): m{x}_epr, m{x}_epi, m{x}_psir, m{x}_psii, m{x}_w for
      x in a, b, c: motor x's E', ψk (network frame, p.u.) and speed (p.u.), as in Cim5bl.
    Flags (arrays (n,)): d_* motor D's flags (Acmtblu1.flags); vmin_e: electronic load's
      deepest dip since it went below Vd1 (p.u.; NO_DIP: none); on{k}{x}: motor x's stage-k
      slice connected (0/1); ttr{k}{x}, trc{k}{x}: time below Vtrk / above Vrck, s.
    """

    name = "CMLDBLU2"
    cons = _CONS_BLU1 + (_FRCEL,)
    states = tuple(f"m{x}_{s}" for x in MOTORS for s in Cim5bl.states)
    flags = (tuple(f"d_{f}" for f in Acmtblu1.flags) + ("vmin_e",)
             + tuple(f"{f}{k}{x}" for x in MOTORS for k in "12" for f in ("on", "ttr", "trc")))
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
        return Acmtblu1.check_combination({a: p[c] for a, c in _D_NAMES})

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
            _, _, epp = Cim5bl._emfs(pm, xm)
            drawn = drawn + _motor_share(p, z, m) * pm["sm"] * Cim5bl._stator_current(pm, epp, v)
        s = _static_power(p, vmag, z["d_fm"] - 1.0) + _electronic_power(p, vmag, z["vmin_e"])
        b = p["b_le"] * jnp.where(p["extra_var"] > 0, _connected_share(p, z, vmag), 1.0)
        return drawn + jnp.conj(s) * v / jnp.maximum(vmag ** 2, 1e-12) + 1j * b * v

    @classmethod
    def derivative(cls, p: Params, x: States, z: States, v: Array) -> States:
        """Rates of motors A-C (Cim5bl equations; shared aggregate state, spec §5)."""
        out = {}
        for m in MOTORS:
            rates = Cim5bl.derivative(_sub(p, f"m{m}_"), _sub(x, f"m{m}_"), {"status": 1.0}, v)
            out.update({f"m{m}_{k}": r for k, r in rates.items()})
        return out

    @classmethod
    def stiff_rates(cls, p: Params, x: States, z: States) -> dict[tuple[str, str], Array]:
        """Motors A-C's stiff E' and ψk rates (`Cim5bl.stiff_rates`)."""
        return {(f"m{m}_{re}", f"m{m}_{im}"): lam for m in MOTORS
                for (re, im), lam in Cim5bl.stiff_rates(_sub(p, f"m{m}_"), _sub(x, f"m{m}_"),
                                                        {}).items()}

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
    cons = _CONS_BLU1
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


# --------------------------------------------------------------------------- #
# Initialisation and network expansion (host, NumPy float64; spec §3, §6, §7)
# --------------------------------------------------------------------------- #

class Expansion(NamedTuple):
    """The case with the composite loads' buses and branches, and the initialised units.

    Attributes:
      case: the expanded case (internal buses appended after the RAW buses).
      vm, va: (n_bus,) power-flow voltages of the expanded case, p.u., rad.
      load_bus: (n,) bus index of each unit's load bus in `case`.
      system_bus: (n,) bus index of each unit's system (RAW) bus.
      params, states, flags: {name: (n,)} of the units (Cmldblu2 layout).
      s0: (n,) complex power each unit draws at its load bus, p.u. system base.
      labels: (n,) "file:line: MODEL at bus B id 'I'".
      names: {internal bus number: name} ("Bus<N>_loadBus", "Bus<N>_lowBus").
    """

    case: Case
    vm: np.ndarray
    va: np.ndarray
    load_bus: np.ndarray
    system_bus: np.ndarray
    params: dict
    states: dict
    flags: dict
    s0: np.ndarray
    labels: tuple[str, ...]
    names: dict[int, str]


def read_records(records: Sequence[DyrRecord]) -> tuple[dict, list[DyrRecord]]:
    """CON arrays of CMLDBLU1/CMLDBLU2 records, stacked in the order of the returned list."""
    ordered, parts = [], []
    for name, model in COMPOSITE_LOADS.items():
        rs = [r for r in records if r.model == name]
        if rs:
            ordered += rs
            parts.append(model.read(rs))
    params = {k: np.concatenate([part[k] for part in parts]) for k in parts[0]}
    return params, ordered


def expand(case: Case, vm: np.ndarray, va: np.ndarray, records: Sequence[DyrRecord],
           options: CompositeOptions, motors: MotorOptions, notes: list[str]) -> Expansion:
    """Add each record's buses and branches to `case` and initialise it (spec §6, §7).

    vm, va (n_bus,): the power-flow solution of `case`. Each record's RAW load record (at
    the solved voltage) is what its substation draws; it moves to the new load bus.
    Appends the load report to `notes`. Raises ModelError naming the record.
    """
    p, records = read_records(records)
    loads, number = case.loads, case.buses.number
    where = {(int(number[loads.bus[k]]), loads.load_id[k].strip().upper()): k
             for k in np.flatnonzero(loads.in_service)}
    units = np.array([where[(r.bus, r.device_id.strip().upper())] for r in records])
    bus = loads.bus[units]
    vmr = vm[bus]
    s_rec = (loads.p_power[units] + 1j * loads.q_power[units]
             + (loads.p_current[units] + 1j * loads.q_current[units]) * vmr
             + (loads.p_impedance[units] + 1j * loads.q_impedance[units]) * vmr ** 2)
    labels = tuple(device_label(r) for r in records)
    for k in np.flatnonzero(~(s_rec.real > 0))[:1]:
        raise ModelError(f"{labels[k]}: the load record draws P = "
                         f"{s_rec[k].real * case.base_mva:g} MW at the power flow; the "
                         "composite load needs P > 0")
    init = initialise(p, s_rec, vmr * np.exp(1j * va[bus]), case.base_mva, case.frequency_hz,
                      options, motors, labels)
    notes.extend(f"load report: {line}" for line in init.notes)
    notes.extend(f"load report: {label}: CMLDBLU1 has no FRCEL: taken as 0"
                 for r, label in zip(records, labels) if r.model == "CMLDBLU1")

    rows = to_rows(case)
    names, load_numbers = {}, []
    for k, (r, ((low, low_name), (load, load_name))) in enumerate(
            zip(records, internal_buses(case, records))):
        names[low], names[load] = low_name, load_name
        load_numbers.append(load)
        parent = rows["buses"][int(bus[k])]
        for n, v, kv in ((low, init.v_low[k], 0.0), (load, init.v_load[k], parent["base_kv"])):
            rows["buses"].append(dict(parent, number=n, name=names[n], kind=PQ, base_kv=kv,
                                      vm=abs(v), va=np.angle(v), line=r.line))
        rows["loads"][int(units[k])] = dict(rows["loads"][int(units[k])], in_service=False)
        rows["loads"].append(dict(rows["loads"][int(units[k])], bus=load, in_service=True,
                                  p_power=init.s0[k].real, q_power=init.s0[k].imag,
                                  p_current=0.0, q_current=0.0, p_impedance=0.0,
                                  q_impedance=0.0))
        rows["shunts"].append(dict(bus=low, shunt_id="cm", in_service=True, g=0.0,
                                   b=init.params["b_low"][k], line=r.line))
        branch = dict(ckt="cm", in_service=True, b=0.0, shift=0.0, g_from=0.0, b_from=0.0,
                      g_to=0.0, b_to=0.0, line=r.line)
        rows["branches"].append(dict(branch, from_bus=low, to_bus=r.bus, r=0.0,
                                     x=init.params["x_xf"][k], tap=init.params["ratio"][k],
                                     is_transformer=True))
        rows["branches"].append(dict(branch, from_bus=low, to_bus=load,
                                     r=init.params["r_fdr"][k], x=init.params["x_fdr"][k],
                                     tap=1.0, is_transformer=False))
    rows["notes"] = tuple(case.notes) + (f"{len(records)} composite load(s): internal buses "
                                         "added (jaxgrid.models.cmld.internal_buses)",)
    expanded = build_case(**rows)
    v_new = np.concatenate([init.v_low, init.v_load])
    order = np.ravel(np.stack([np.arange(len(records)), np.arange(len(records)) + len(records)],
                              axis=1))
    v_new = v_new[order]
    return Expansion(case=expanded, vm=np.concatenate([vm, np.abs(v_new)]),
                     va=np.concatenate([va, np.angle(v_new)]),
                     load_bus=expanded.bus_index(load_numbers), system_bus=bus,
                     params=init.params,
                     states=init.states, flags=init.flags, s0=init.s0, labels=labels,
                     names=names)


def internal_buses(case: Case, records: Sequence[DyrRecord]):
    """[((low-side number, name), (load-bus number, name))] per composite-load record.

    For a record at RAW bus N: N + M·(2j + 1) "Bus<N>_lowBus" and N + M·(2j + 2)
    "Bus<N>_loadBus", M the smallest power of ten above every |bus number| of `case`, j the
    number of earlier records (in `records` order) at the same bus; j > 0 appends
    "_<LID>" to both names. Both buses take N's area and zone; the load bus takes N's base
    kV and the low-side bus 0 kV, so that a "zone Z above X kV" observation rule picks the
    load buses and not the low sides (the study's 300-bus task: 108 zone-1 buses above
    60 kV + 46 load buses = its 154 observed buses).
    """
    top = 10 ** len(str(int(np.abs(case.buses.number).max())))
    seen: dict[int, int] = {}
    out = []
    for r in records:
        j = seen[r.bus] = seen.get(r.bus, -1) + 1
        tail = "" if j == 0 else f"_{r.device_id.strip()}"
        out.append(((r.bus + top * (2 * j + 1), f"Bus{r.bus}_lowBus{tail}"),
                    (r.bus + top * (2 * j + 2), f"Bus{r.bus}_loadBus{tail}")))
    return out


class Initialised(NamedTuple):
    """`initialise`'s result, arrays (n,): params, states, flags (dicts), s0 (complex power
    drawn at the load bus, p.u. system base), v_low, v_load (complex p.u.), notes."""

    params: dict
    states: dict
    flags: dict
    s0: np.ndarray
    v_low: np.ndarray
    v_load: np.ndarray
    notes: list[str]


def load_base(p: dict, p_sys: np.ndarray, sbase: float) -> np.ndarray:
    """Load MVA base Sb_L (n,), p.u. of the system base, from MVA and the load P (§2.1 k=0)."""
    mva = p["mva"]
    by_factor = p_sys / np.abs(np.where(mva < 0, mva, 1.0))
    return np.where(mva > 0, mva / sbase, np.where(mva < 0, by_factor, p_sys / 0.8))


def initial_tap(p: dict, s: np.ndarray, vs_mag: np.ndarray, x: np.ndarray) -> np.ndarray:
    """LTC tap (n,) of spec §6 step 1: low-side voltage near the band centre, on a step."""
    vt = 0.5 * (p["vmin"] + p["vmax"])
    t = np.sqrt((vs_mag * vt) ** 2 / ((s.imag * x - vs_mag ** 2) ** 2 + (x * s.real) ** 2))
    stepped = 1.0 + np.round((t - 1.0) / np.where(p["step"] > 0, p["step"], 1.0)) * p["step"]
    return np.clip(np.where(p["step"] > 0, stepped, t), p["tmin"], p["tmax"])


def fractions(p: dict) -> dict[str, np.ndarray]:
    """Shares of the load-bus P per component (§3): a-d, el, st; scaled when ΣF > 1."""
    given = {"a": p["fma"], "b": p["fmb"], "c": p["fmc"], "d": p["fmd"], "el": p["fel"]}
    total = sum(given.values())
    scale = np.where(total > 1.0, 1.0 / np.maximum(total, 1e-300), 1.0)
    out = {k: v * scale for k, v in given.items()}
    out["st"] = np.where(total > 1.0, 0.0, 1.0 - total)
    return out


def _motor_constants(p: dict, m: str, omega_b, stiff_below: float) -> dict:
    """Constants of motor m for the Cim5bl functions (p.u. on its base, s)."""
    lpp = p[f"lpp{m}"]
    c = transient_constants(p[f"ls{m}"], p[f"lp{m}"], lpp, LL_OVER_LPP * lpp, p[f"tpo{m}"],
                            p[f"tppo{m}"], (lpp < p[f"lp{m}"]) & (p[f"tppo{m}"] > 0),
                            stiff_below)
    zero = np.zeros_like(lpp)
    return dict(c, ra=p[f"rs{m}"], omega_b=omega_b, sat_a=zero, sat_b=zero, h=p[f"h{m}"],
                d=p[f"etrq{m}"])


def _motor_d_params(p: dict) -> dict:
    return {a: p[c] for a, c in _D_NAMES}


def _components(p, share, consts, vmag, p_load, sbase, f_nom, motors, labels):
    """Per component, complex power (n,) drawn at |V_L| = vmag for load-bus P = p_load.

    Returns ({"a".."d", "el", "st": S, p.u. system base}, motor-D init, slips {a, b, c}).
    The static load takes up any difference of motor D's P from its share (curve_offsets).
    """
    out, slips = {}, {}
    for m in MOTORS:
        s0, problem = solve_slip(consts[m], vmag, p[f"lfm{m}"])
        for k in np.flatnonzero(problem != ""):
            raise ModelError(f"{labels[k]}: motor {m.upper()} cannot carry its load at "
                             f"V_L = {vmag[k]:.4f} p.u.: {problem[k]}")
        z = steady_state(consts[m], s0, vmag)[2]
        out[m] = share[m] * p_load / p[f"lfm{m}"] * vmag ** 2 / np.conj(z)
        slips[m] = s0
    site = LoadSite(v0=vmag.astype(complex), record_p=share["d"] * p_load, bus_p=p_load,
                    sbase=sbase, f_nom=f_nom, labels=tuple(f"{lb} motor D" for lb in labels))
    d = Acmtblu1.init(_motor_d_params(p), site, dataclasses.replace(
        motors, share_mode="psse_load_record"))
    out["d"] = d[3]
    out["el"] = share["el"] * p_load * (1.0 + 1j * _tan(p["pfel"]))
    p_st = share["st"] * p_load + (share["d"] * p_load - d[3].real)
    out["st"] = p_st + 1j * share["st"] * p_load * _tan(p["pfs"])
    return out, d, slips


def _tan(pf):
    """tan(acos|pf|)·sign(pf): reactive per active power of a power factor (§4)."""
    return np.tan(np.arccos(np.abs(pf))) * np.where(pf < 0, -1.0, 1.0)


def initialise(p: dict, s: np.ndarray, vs: np.ndarray, sbase: float, f_nom: float,
               options: CompositeOptions, motors: MotorOptions,
               labels: Sequence[str]) -> Initialised:
    """Initialise n composite loads from the system side (spec §6).

    p: CON arrays (n,); s (n,): the load record's complex power at the solved voltage vs (n,)
    complex, p.u. system base. Returns the units and their internal bus voltages.
    """
    p = {k: np.asarray(v, dtype=float) for k, v in p.items()}
    notes: list[str] = []
    n = s.shape[0]
    sbl = load_base(p, s.real, sbase)
    share = fractions(p)
    x_xf = p["xxf"] / sbl * p["tfixhs"] ** 2
    tap = initial_tap(p, s, np.abs(vs), x_xf)
    ratio = p["tfixls"] * tap / p["tfixhs"]
    i_s = np.conj(s / vs)
    v_low = ratio * (vs - 1j * x_xf * i_s)
    i_low = i_s / ratio
    b_ss = p["bss"] * sbl
    omega_b = np.full(n, 2 * np.pi * f_nom)
    consts = {m: _motor_constants(p, m, omega_b, motors.stiff_below) for m in MOTORS}

    def feeder(bf, scale):
        z_f = scale * (p["rfdr"] + 1j * p["xfdr"]) / sbl
        i_f = i_low - 1j * (b_ss + p["fb"] * bf) * v_low
        v_l = v_low - z_f * i_f
        return v_l, v_l * np.conj(i_f) + 1j * (1.0 - p["fb"]) * bf * np.abs(v_l) ** 2

    def mismatch(bf, scale):
        v_l, s_l = feeder(bf, scale)
        comp, _, _ = _components(p, share, consts, np.abs(v_l), np.ones(n), sbase, f_nom,
                                 motors, labels)
        return s_l.imag - s_l.real * sum(comp.values()).imag

    def solve_bf(scale):
        if options.compensation == "static_q":
            return np.zeros(n)
        b0, b1 = np.zeros(n), 0.1 * s.real
        g0 = mismatch(b0, scale)
        for _ in range(SECANT_STEPS):
            g1 = mismatch(b1, scale)
            if np.abs(g1).max() < SECANT_TOL:
                return b1
            slope = np.where(b1 != b0, (g1 - g0) / np.where(b1 != b0, b1 - b0, 1.0), 1.0)
            b0, g0, b1 = b1, g1, b1 - g1 / np.where(slope != 0, slope, 1.0)
        bad = np.flatnonzero(np.abs(g1) >= 1e-9)
        if bad.size:
            raise ModelError(f"{labels[bad[0]]}: feeder compensation Bf did not converge "
                             f"(reactive mismatch {g1[bad[0]]:.3g} p.u.)")
        return b1

    scale = np.ones(n)
    bf = solve_bf(scale)
    v_first = np.abs(feeder(bf, scale)[0])
    for _ in range(int(round(1.0 / options.floor_step))):
        low = (np.abs(feeder(bf, scale)[0]) < options.v_floor) & (scale > options.floor_step)
        if not low.any():
            break
        scale = np.where(low, scale - options.floor_step, scale)
        bf = solve_bf(scale)
    v_l, s_l = feeder(bf, scale)
    p_l = s_l.real
    for k in np.flatnonzero(scale < 1.0):
        notes.append(f"{labels[k]}: |V_L| = {v_first[k]:.4f} p.u. < {options.v_floor:g}: "
                     f"feeder impedance scaled to {scale[k]:.2f} × (RFDR + jXFDR), |V_L| = "
                     f"{abs(v_l[k]):.4f} p.u. (spec §6 step 6)")
    for k in np.flatnonzero(np.abs(v_l) < options.v_floor):
        notes.append(f"{labels[k]}: |V_L| = {abs(v_l[k]):.4f} p.u. stays below the floor "
                     f"{options.v_floor:g}")

    vmag = np.abs(v_l)
    comp, (pd, _, zd, s_d, d_notes), slips = _components(
        p, share, consts, vmag, p_l, sbase, f_nom, motors, labels)
    notes.extend(d_notes)
    if options.compensation == "static_q":  # the static load's Q closes the balance
        comp["st"] = comp["st"] + 1j * (s_l.imag - sum(comp.values()).imag)
    params, states = dict(p), {}
    b_le = (1.0 - p["fb"]) * bf
    y_norton = pd["y_norton"] + np.conj(comp["el"] + comp["st"]) / vmag ** 2 + 1j * b_le
    drawn = s_d + comp["el"] + comp["st"] - 1j * b_le * vmag ** 2
    for m in MOTORS:
        c = consts[m]
        sm = share[m] * p_l / p[f"lfm{m}"]
        alpha, beta, z, _ = steady_state(c, slips[m], vmag)
        i0 = v_l / z
        ep0, psik0 = alpha * i0, beta * i0
        te0 = np.real((c["k5"] * ep0 + c["k4"] * psik0) * np.conj(i0))
        torque, _ = Cim5bl.torque_constants(c, 1.0 - slips[m], te0)
        params.update({f"m{m}_{k}": v for k, v in dict(c, **torque, sm=sm).items()})
        states.update({f"m{m}_epr": ep0.real, f"m{m}_epi": ep0.imag, f"m{m}_psir": psik0.real,
                       f"m{m}_psii": psik0.imag, f"m{m}_w": 1.0 - slips[m]})
        y_norton = y_norton + sm / (c["ra"] + 1j * c["lpp"])
        drawn = drawn + sm * v_l * np.conj(i0)
    params.update({f"d_{k}": v for k, v in pd.items()})
    params.update(
        sbl=sbl, tap=tap, ratio=ratio, x_xf=x_xf, r_fdr=scale * p["rfdr"] / sbl,
        x_fdr=scale * p["xfdr"] / sbl, bf=bf, b_low=b_ss + p["fb"] * bf, b_le=b_le, p_l=p_l,
        v_l0=vmag, p_el0=share["el"] * p_l, tan_el=_tan(p["pfel"]), p_st0=comp["st"].real,
        q_st0=comp["st"].imag, extra_var=np.full(n, float(options.extra_var == "load_end")),
        w_a=share["a"], w_b=share["b"], w_c=share["c"], w_d=share["d"], w_el=share["el"],
        w_st=comp["st"].real / p_l, y_norton=y_norton)
    flags = {f"d_{k}": v for k, v in zd.items()}
    flags["vmin_e"] = np.full(n, NO_DIP)
    for m in MOTORS:
        for k in "12":
            flags.update({f"on{k}{m}": np.ones(n), f"ttr{k}{m}": np.zeros(n),
                          f"trc{k}{m}": np.zeros(n)})
    for k in range(n):
        dropped = [m.upper() for m in MOTORS if consts[m]["double"][k] == 0
                   and p[f"lpp{m}"][k] < p[f"lp{m}"][k] and p[f"tppo{m}"][k] > 0]
        notes.append(
            f"{labels[k]}: P_L = {p_l[k] * sbase:.2f} MW at |V_L| = {vmag[k]:.4f} p.u. "
            f"(low side {abs(v_low[k]):.4f}), Sb_L = {sbl[k] * sbase:.2f} MVA, tap {tap[k]:.5f}, "
            f"Bf = {bf[k] / sbl[k]:.4f} p.u. load base, shares A {share['a'][k]:.3f} "
            f"B {share['b'][k]:.3f} C {share['c'][k]:.3f} D {share['d'][k]:.3f} "
            f"el {share['el'][k]:.3f} static {share['st'][k]:.3f}"
            + (f"; subtransient stage of motor(s) {', '.join(dropped)} dropped (Tppo < "
               f"{motors.stiff_below:g} s)" if dropped else ""))
        if abs(comp["st"][k].real - share["st"][k] * p_l[k]) > 1e-9:
            notes.append(f"{labels[k]}: motor D draws {s_d[k].real * sbase:.3f} MW at V_L, not "
                         f"its share; the static load takes the difference")
    return Initialised(params=params, states=states, flags=flags, s0=drawn, v_low=v_low,
                       v_load=v_l, notes=notes)
