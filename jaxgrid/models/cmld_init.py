"""Initialisation of the WECC composite load and its network expansion (`shared/specs/cmld.md`
§3, §6, §7; host, NumPy float64).

`initialise` starts the units from the system side (`Cmldblu2.init` calls it); `expand` then
adds each unit's low-side and load buses and branches to the case; the model itself is
`jaxgrid.models.cmld` (its docstring lists the readings), the CONs `jaxgrid.models.cmld_cons`.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from jaxgrid.case import PQ, Case, build_case, to_rows
from jaxgrid.records import DyrRecord
from jaxgrid.models.acmotor import NO_DIP, Acmtblu1
from jaxgrid.models.base import Initial, LoadSite, ModelError, device_label
from jaxgrid.models.cmld_cons import MOTOR_D_NAMES, MOTORS
from jaxgrid.models.induction import (Cim5bl, motor_constants, motorw_circuit, solve_slip,
                                      steady_state, transient_constants)
from jaxgrid.models.options import CompositeOptions, MotorOptions

LL_OVER_LPP = 0.8  # Ll/Lpp of the circuit realising motors A-C (any Ll < Lpp: the same motor)
SECANT_STEPS = 60  # iterations of the Bf root find (converges in < 10)
SECANT_TOL = 1e-13  # p.u. system base: reactive mismatch accepted at the load bus


class Expansion(NamedTuple):
    """The case with the composite loads' buses and branches.

    Attributes:
      case: the expanded case (internal buses appended after the RAW buses).
      vm, va: (n_bus,) power-flow voltages of the expanded case, p.u., rad.
      units: (n,) index in `case.loads` of each unit's load record, moved to its load bus.
      system_bus: (n,) bus index of each unit's system (RAW) bus.
      names: {internal bus number: name} ("Bus<N>_loadBus", "Bus<N>_lowBus").
    """

    case: Case
    vm: np.ndarray
    va: np.ndarray
    units: np.ndarray
    system_bus: np.ndarray
    names: dict[int, str]


def expand(case: Case, vm: np.ndarray, va: np.ndarray, records: Sequence[DyrRecord],
           units: Sequence[int], start: Initial, notes: list[str]) -> Expansion:
    """Add each started unit's buses and branches to `case` (spec §7).

    vm, va (n_bus,): the power-flow solution of `case`; records (n,): the units' DYR records,
    units (n,): their RAW load records (indices in `case.loads`), start: their `Initial`
    (`Cmldblu2.init`: b_low, x_xf, ratio, r_fdr, x_fdr; v_low, v_load, s0). Each load
    record moves to its new load bus with the power s0 the feeder delivers there. Appends
    the CMLDBLU1 report (no FRCEL) to `notes`.
    """
    units = np.asarray(units, dtype=int)
    bus = case.loads.bus[units]
    params = {k: np.asarray(start.params[k]) for k in ("b_low", "x_xf", "ratio", "r_fdr",
                                                       "x_fdr")}
    v_low, v_load, s0 = (np.asarray(start.output[k]) for k in ("v_low", "v_load", "s0"))
    notes.extend(f"load report: {device_label(r)}: CMLDBLU1 has no FRCEL: taken as 0"
                 for r in records if r.model == "CMLDBLU1")

    rows = to_rows(case)
    names, moved = {}, []
    for k, (r, ((low, low_name), (load, load_name))) in enumerate(
            zip(records, internal_buses(case, records))):
        names[low], names[load] = low_name, load_name
        parent = rows["buses"][int(bus[k])]
        for n, v, kv in ((low, v_low[k], 0.0), (load, v_load[k], parent["base_kv"])):
            rows["buses"].append(dict(parent, number=n, name=names[n], kind=PQ, base_kv=kv,
                                      vm=abs(v), va=np.angle(v), line=r.line))
        rows["loads"][int(units[k])] = dict(rows["loads"][int(units[k])], in_service=False)
        moved.append(len(rows["loads"]))
        rows["loads"].append(dict(rows["loads"][int(units[k])], bus=load, in_service=True,
                                  p_power=s0[k].real, q_power=s0[k].imag,
                                  p_current=0.0, q_current=0.0, p_impedance=0.0,
                                  q_impedance=0.0))
        rows["shunts"].append(dict(bus=low, shunt_id="cm", in_service=True, g=0.0,
                                   b=params["b_low"][k], line=r.line))
        branch = dict(ckt="cm", in_service=True, b=0.0, shift=0.0, g_from=0.0, b_from=0.0,
                      g_to=0.0, b_to=0.0, line=r.line)
        rows["branches"].append(dict(branch, from_bus=low, to_bus=r.bus, r=0.0,
                                     x=params["x_xf"][k], tap=params["ratio"][k],
                                     is_transformer=True))
        rows["branches"].append(dict(branch, from_bus=low, to_bus=load,
                                     r=params["r_fdr"][k], x=params["x_fdr"][k],
                                     tap=1.0, is_transformer=False))
    rows["notes"] = tuple(case.notes) + (f"{len(records)} composite load(s): internal buses "
                                         "added (jaxgrid.models.cmld_init.internal_buses)",)
    expanded = build_case(**rows)
    v_new = np.ravel(np.stack([v_low, v_load], axis=1))
    return Expansion(case=expanded, vm=np.concatenate([vm, np.abs(v_new)]),
                     va=np.concatenate([va, np.angle(v_new)]), units=np.array(moved),
                     system_bus=bus, names=names)


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
    """Constants of motor m for the Cim5bl functions (p.u. on its base, s): the WECC motorw
    form of spec §6 (Ls, Lp, Lpp, Tpo, Tppo), exactly, through its equivalent circuit
    (`induction.motorw_circuit`, Ll = LL_OVER_LPP·Lpp); a subtransient stage with
    Tppo < stiff_below (s) is dropped (Lpp := Lp, single cage, the same form)."""
    ls, lp, lpp, tpo, tppo = (p[f"{k}{m}"] for k in ("ls", "lp", "lpp", "tpo", "tppo"))
    double = (lpp < lp) & (tppo > 0) & (tppo >= stiff_below)
    ll = LL_OVER_LPP * lpp
    with np.errstate(divide="ignore", invalid="ignore"):
        circuit = motorw_circuit(ls, lp, np.where(double, lpp, 0.5 * lp), tpo,
                                 np.where(double, tppo, 1.0), np.where(double, ll, 0.4 * lp),
                                 omega_b)
    two = motor_constants(circuit, omega_b, stiff_below=0.0)
    one = transient_constants(ls, lp, lp, ll, tpo, 0.0 * tpo, np.zeros(lp.shape, bool), 0.0)
    c = {k: np.where(double, two[k], one[k]) for k in one}
    zero = np.zeros_like(lpp)
    return dict(c, ra=p[f"rs{m}"], omega_b=omega_b, sat_a=zero, sat_b=zero, h=p[f"h{m}"],
                d=p[f"etrq{m}"])


def _motor_d_params(p: dict) -> dict:
    return {a: p[c] for a, c in MOTOR_D_NAMES}


def _components(p, share, consts, vmag, p_load, sbase, f_nom, motors, labels):
    """Per component, complex power (n,) drawn at |V_L| = vmag for load-bus P = p_load.

    Returns ({"a".."d", "el", "st": S, p.u. system base}, motor D's `Initial`, slips {a, b,
    c}).
    The static load takes up any difference of motor D's P from its share (curve_offsets).
    """
    n = vmag.shape[0]
    # motors A-C solved as one stack of 3n motors (the same numbers, a third of the NumPy
    # calls: this solve runs in every step of the feeder's root finds)
    stacked = {k: np.concatenate([np.broadcast_to(consts[m][k], (n,)) for m in MOTORS])
               for k in consts[MOTORS[0]]}
    vmags = np.tile(vmag, len(MOTORS))
    s0, problem = solve_slip(stacked, vmags, np.concatenate([p[f"lfm{m}"] for m in MOTORS]))
    for k in np.flatnonzero(problem != ""):
        raise ModelError(f"{labels[k % n]}: motor {MOTORS[k // n].upper()} cannot carry its "
                         f"load at V_L = {vmag[k % n]:.4f} p.u.: {problem[k]}")
    z = steady_state(stacked, s0, vmags)[2].reshape(len(MOTORS), n)
    out, slips = {}, {}
    for i, m in enumerate(MOTORS):
        out[m] = share[m] * p_load / p[f"lfm{m}"] * vmag ** 2 / np.conj(z[i])
        slips[m] = s0[i * n:(i + 1) * n]
    site = LoadSite(v0=vmag.astype(complex), record_s=share["d"] * p_load, bus_p=p_load,
                    sbase=sbase, f_nom=f_nom, labels=tuple(f"{lb} motor D" for lb in labels),
                    motors=dataclasses.replace(motors, share_mode="psse_load_record"))
    d = Acmtblu1.init(_motor_d_params(p), site)
    out["d"] = d.output["s0"]
    out["el"] = share["el"] * p_load * (1.0 + 1j * _tan(p["pfel"]))
    p_st = share["st"] * p_load + (share["d"] * p_load - out["d"].real)
    out["st"] = p_st + 1j * share["st"] * p_load * _tan(p["pfs"])
    return out, d, slips


def _tan(pf):
    """tan(acos|pf|)·sign(pf): reactive per active power of a power factor (§4)."""
    return np.tan(np.arccos(np.abs(pf))) * np.where(pf < 0, -1.0, 1.0)


def floor_scales(step: float) -> np.ndarray:
    """The feeder-impedance scales of the voltage floor (spec §6 step 6): 1, 1 − step, ...
    by repeated subtraction (as a tool stepping down would), while above `step`, at most
    round(1/step) steps."""
    scales = [1.0]
    while len(scales) <= round(1.0 / step) and scales[-1] > step:
        scales.append(scales[-1] - step)
    return np.array(scales)


def floor_steps(v_load, v_first: np.ndarray, scales: np.ndarray,
                v_floor: float) -> np.ndarray:
    """(n,) int: per load, the fewest steps along `scales` (`floor_scales`) that lift |V_L|
    to `v_floor` p.u. (the last step where none does), given v_load(scale (n,)) -> |V_L|
    (n,) and v_first = v_load(1).

    |V_L| rises as the feeder impedance falls, so the steps are bisected (about log2 of
    their count solves, for all loads at once) rather than taken one by one.
    """
    last = len(scales) - 1
    lo = np.zeros(v_first.shape, int)  # fails (|V_L| < v_floor) where lo < hi
    hi = np.where(v_first < v_floor, last, 0)  # passes, or is the last step
    while (hi - lo > 1).any():
        mid = np.where(hi - lo > 1, (lo + hi) // 2, hi)
        lifted = v_load(scales[mid]) >= v_floor
        lo, hi = np.where(lifted, lo, mid), np.where(lifted, mid, hi)
    return hi


INTERPSS_LFMD = 0.85  # InterPSS's motor-D loading factor: its mapper leaves LFmD unread


def interpss_cons(p: dict, no_ac: bool) -> dict:
    """CON arrays (n,) as the InterPSS of the RLGC environments reads them (../shared/
    reference/interpss-cmld.md): LFmD 0.85; motors A-C with load torque ∝ ω² and no UV
    trips; the electronic and static loads one constant-impedance remainder (P and Q ∝ V²,
    no frequency terms; its Q closes the balance, `initialise` with reading != "wecc");
    no_ac: motors A-C in that remainder too. Motor D's curves are InterPSS's defaults, which
    are the PNNL data's values."""
    q = dict(p, lfmd=np.full_like(p["lfmd"], INTERPSS_LFMD), fel=0.0 * p["fel"],
             p1e=2.0 + 0.0 * p["p1e"], p1c=1.0 + 0.0 * p["p1c"], p2c=0.0 * p["p2c"],
             q1e=2.0 + 0.0 * p["q1e"], q1c=1.0 + 0.0 * p["q1c"], q2c=0.0 * p["q2c"],
             pfrq=0.0 * p["pfrq"], qfrq=0.0 * p["qfrq"])
    for m in MOTORS:
        q.update({f"etrq{m}": 2.0 + 0.0 * p[f"etrq{m}"], f"vtr1{m}": 0.0 * p[f"vtr1{m}"],
                  f"vtr2{m}": 0.0 * p[f"vtr2{m}"]})
        if no_ac:
            q[f"fm{m}"] = 0.0 * p[f"fm{m}"]
    return q


class _Substation(NamedTuple):
    """The substation transformer of n units at its initial tap (spec §6 step 1), arrays (n,):
    sbl (load MVA base), x_xf, tap, ratio (low side per system side), v_low, i_low (complex
    low-side voltage and current), b_ss (shunt), p.u. system base."""

    sbl: np.ndarray
    x_xf: np.ndarray
    tap: np.ndarray
    ratio: np.ndarray
    v_low: np.ndarray
    i_low: np.ndarray
    b_ss: np.ndarray


def _substation(p: dict, s: np.ndarray, vs: np.ndarray, sbase: float) -> _Substation:
    """The units' `_Substation` for the load record's power s (n,) at the voltage vs (n,)."""
    sbl = load_base(p, s.real, sbase)
    x_xf = p["xxf"] / sbl * p["tfixhs"] ** 2
    tap = initial_tap(p, s, np.abs(vs), x_xf)
    ratio = p["tfixls"] * tap / p["tfixhs"]
    i_s = np.conj(s / vs)
    return _Substation(sbl, x_xf, tap, ratio, v_low=ratio * (vs - 1j * x_xf * i_s),
                       i_low=i_s / ratio, b_ss=p["bss"] * sbl)


class _Feeder(NamedTuple):
    """The feeder of n units as initialised (spec §6 steps 2-6), arrays (n,): bf (its
    compensation), scale (of its impedance, the voltage floor's), v_l and s_l (complex
    load-bus voltage and power), p.u. system base."""

    bf: np.ndarray
    scale: np.ndarray
    v_l: np.ndarray
    s_l: np.ndarray


def _feeder(p: dict, s: np.ndarray, sub: _Substation, share: dict, consts: dict, sbase: float,
            f_nom: float, options: CompositeOptions, motors: MotorOptions,
            labels: Sequence[str], notes: list[str]) -> _Feeder:
    """The feeder's compensation Bf (a secant root find of the load bus's reactive balance,
    none with compensation "static_q") and the impedance scale that lifts |V_L| to the
    voltage floor; what the floor changed is appended to `notes`."""
    n = s.shape[0]

    def feeder(bf, scale):
        z_f = scale * (p["rfdr"] + 1j * p["xfdr"]) / sub.sbl
        i_f = sub.i_low - 1j * (sub.b_ss + p["fb"] * bf) * sub.v_low
        v_l = sub.v_low - z_f * i_f
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

    def v_load(scale):
        return np.abs(feeder(solve_bf(scale), scale)[0])

    bf = solve_bf(np.ones(n))
    v_first = np.abs(feeder(bf, 1.0)[0])
    scales = floor_scales(options.floor_step)
    scale = scales[floor_steps(v_load, v_first, scales, options.v_floor)]
    if (scale < 1.0).any():  # else the first solve stands
        bf = solve_bf(scale)
    v_l, s_l = feeder(bf, scale)
    for k in np.flatnonzero(scale < 1.0):
        notes.append(f"{labels[k]}: |V_L| = {v_first[k]:.4f} p.u. < {options.v_floor:g}: "
                     f"feeder impedance scaled to {scale[k]:.2f} × (RFDR + jXFDR), |V_L| = "
                     f"{abs(v_l[k]):.4f} p.u. (spec §6 step 6)")
    for k in np.flatnonzero(np.abs(v_l) < options.v_floor):
        notes.append(f"{labels[k]}: |V_L| = {abs(v_l[k]):.4f} p.u. stays below the floor "
                     f"{options.v_floor:g}")
    return _Feeder(bf, scale, v_l, s_l)


def initialise(p: dict, s: np.ndarray, vs: np.ndarray, sbase: float, f_nom: float,
               options: CompositeOptions, motors: MotorOptions,
               labels: Sequence[str]) -> Initialised:
    """Initialise n composite loads from the system side (spec §6): the substation
    (`_substation`), the feeder (`_feeder`), then every component at the load bus.

    p: CON arrays (n,); s (n,): the load record's complex power at the solved voltage vs (n,)
    complex, p.u. system base. Returns the units and their internal bus voltages.
    """
    p = {k: np.asarray(v, dtype=float) for k, v in p.items()}
    notes: list[str] = []
    if options.reading != "wecc":
        p = interpss_cons(p, no_ac=options.reading == "interpss_no_ac")
        options = dataclasses.replace(options, compensation="static_q")
        notes.append(f"{len(labels)} composite load(s) read as InterPSS reads them "
                     f"({options.reading}; cmld_init.interpss_cons)")
    n = s.shape[0]
    sub = _substation(p, s, vs, sbase)
    share = fractions(p)
    omega_b = np.full(n, 2 * np.pi * f_nom)
    consts = {m: _motor_constants(p, m, omega_b, motors.stiff_below) for m in MOTORS}
    fdr = _feeder(p, s, sub, share, consts, sbase, f_nom, options, motors, labels, notes)
    v_l, p_l, bf = fdr.v_l, fdr.s_l.real, fdr.bf
    vmag = np.abs(v_l)
    comp, d, slips = _components(p, share, consts, vmag, p_l, sbase, f_nom, motors, labels)
    pd, zd, s_d = d.params, d.flags, d.output["s0"]
    notes.extend(d.report)
    if options.compensation == "static_q":  # the static load's Q closes the balance
        comp["st"] = comp["st"] + 1j * (fdr.s_l.imag - sum(comp.values()).imag)
    b_le = (1.0 - p["fb"]) * bf
    y_norton = pd["y_norton"] + np.conj(comp["el"] + comp["st"]) / vmag ** 2 + 1j * b_le
    drawn = s_d + comp["el"] + comp["st"] - 1j * b_le * vmag ** 2
    params, states, y_norton, drawn = _motors_abc(p, consts, share, slips, p_l, v_l, vmag,
                                                  y_norton, drawn)
    params.update({f"d_{k}": v for k, v in pd.items()})
    params.update(
        sbl=sub.sbl, tap=sub.tap, ratio=sub.ratio, x_xf=sub.x_xf,
        r_fdr=fdr.scale * p["rfdr"] / sub.sbl, x_fdr=fdr.scale * p["xfdr"] / sub.sbl, bf=bf,
        b_low=sub.b_ss + p["fb"] * bf, b_le=b_le, p_l=p_l, v_l0=vmag,
        p_el0=share["el"] * p_l, tan_el=_tan(p["pfel"]), p_st0=comp["st"].real,
        q_st0=comp["st"].imag, extra_var=np.full(n, float(options.extra_var == "load_end")),
        w_a=share["a"], w_b=share["b"], w_c=share["c"], w_d=share["d"], w_el=share["el"],
        w_st=comp["st"].real / p_l, y_norton=y_norton)
    notes.extend(_unit_notes(p, sub, fdr, share, comp, s_d, consts, sbase, motors, labels))
    return Initialised(params=params, states=states, flags=_initial_flags(zd, n), s0=drawn,
                       v_low=sub.v_low, v_load=v_l, notes=notes)


def _motors_abc(p: dict, consts: dict, share: dict, slips: dict, p_l, v_l, vmag, y_norton,
                drawn):
    """(params, states, y_norton, drawn): the CONs `p` with motors A-C's constants and
    torques added (prefixed "ma_" ...), their states at their slips, and each one's Norton
    admittance and drawn power added to `y_norton` and `drawn` (n,), p.u. system base."""
    params, states = dict(p), {}
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
    return params, states, y_norton, drawn


def _initial_flags(zd: dict, n: int) -> dict:
    """The units' flags at rest: motor D's (prefixed "d_"), no voltage dip seen, every motor
    A-C part running with its trip timers at zero."""
    flags = {f"d_{k}": v for k, v in zd.items()}
    flags["vmin_e"] = np.full(n, NO_DIP)
    for m in MOTORS:
        for k in "12":
            flags.update({f"on{k}{m}": np.ones(n), f"ttr{k}{m}": np.zeros(n),
                          f"trc{k}{m}": np.zeros(n)})
    return flags


def _unit_notes(p: dict, sub: _Substation, fdr: _Feeder, share: dict, comp: dict, s_d,
                consts: dict, sbase: float, motors: MotorOptions,
                labels: Sequence[str]) -> list[str]:
    """One line per unit of what it was initialised to, and one where motor D draws other
    than its share."""
    notes, p_l, vmag = [], fdr.s_l.real, np.abs(fdr.v_l)
    for k in range(p_l.shape[0]):
        dropped = [m.upper() for m in MOTORS if consts[m]["double"][k] == 0
                   and p[f"lpp{m}"][k] < p[f"lp{m}"][k] and p[f"tppo{m}"][k] > 0]
        notes.append(
            f"{labels[k]}: P_L = {p_l[k] * sbase:.2f} MW at |V_L| = {vmag[k]:.4f} p.u. "
            f"(low side {abs(sub.v_low[k]):.4f}), Sb_L = {sub.sbl[k] * sbase:.2f} MVA, tap "
            f"{sub.tap[k]:.5f}, Bf = {fdr.bf[k] / sub.sbl[k]:.4f} p.u. load base, shares A "
            f"{share['a'][k]:.3f} B {share['b'][k]:.3f} C {share['c'][k]:.3f} D "
            f"{share['d'][k]:.3f} el {share['el'][k]:.3f} static {share['st'][k]:.3f}"
            + (f"; subtransient stage of motor(s) {', '.join(dropped)} dropped (Tppo < "
               f"{motors.stiff_below:g} s)" if dropped else ""))
        if abs(comp["st"][k].real - share["st"][k] * p_l[k]) > 1e-9:
            notes.append(f"{labels[k]}: motor D draws {s_d[k].real * sbase:.3f} MW at V_L, not "
                         f"its share; the static load takes the difference")
    return notes
