"""Built-in FIDVR study cases: `ieee39_fidvr` and `ieee300_fidvr` (network + dynamics + task).

Each builder returns a `StudyCase`: a `Case`, its dynamic records (a `DyrData` built here, source
"jaxgrid.cases.<name>", line = record index), the buses the load-shedding task observes and acts
on, the motor buses, the integration step, the operating point, the study's reward values and
its train and test fault sets: the input of a built-in study, which
`jaxgrid.study.sources.builtin_source` turns into the study's defaults (`jaxgrid.study.builtin`
makes a `Study` of them). Everything is built by this module from public data (MATPOWER networks as shipped by PYPOWER, textbook machine data, the
ACMTBLU1 specification); the PNNL PARS study files were read for facts (bus numbers, which load
carries a motor, typical parameter values), nothing is read from them.

ieee39_fidvr (dt = 2 ms, as the PNNL 39-bus configuration; 1 network sweep, measured)
  Network: the `ieee39` builder (MATPOWER case39; the loads of buses 4, 7, 8, 18 behind
  X = 0.003 p.u. transformers on buses 504, 507, 508, 518, split 40/40/20 % into load IDs 1-3).
  Motors: one ACMTBLU1 record on load ID 2 (40 % of the bus load) at 504, 507 and 518, as in the
  PNNL file IEEE39bus_3AC.dyr (508's record is commented out there); CONs as in that file, which
  are the typical WECC values of the spec (`ACMTBLU1_39`). Task (PNNL
  IEEE39_RL_loadShedding_3motor_continuous.json): observed buses 4, 504, 7, 507, 8, 508, 18, 518;
  action buses 504, 507, 518.
  Machines: GENROU with the New England machine data of Pai (1989, after Athay et al. 1979), on
  100 MVA: H, Xl, Xd, X'd, T'do, Xq, X'q, T'qo per unit (`PAI_39`); bus 39 is the equivalent of
  the rest of the interconnection (H = 500 s on 100 MVA). That data set is two-axis, so the
  subtransient values are typical ones: X''d = X''q = 0.8 X'd, T''do = 0.03 s, T''qo = 0.05 s;
  D = 0; no saturation (Pai gives none). The hydro unit at bus 30 has no q-axis transient
  winding (Pai: T'qo = 0, X'q < X'd); GENROU needs X''q < X'q, so it gets X'q = Xq (the q-axis
  transient circuit then carries no flux) and T'qo = 1 s.

ieee300_fidvr (dt = 5 ms, 1 network sweep, measured)
  Network: MATPOWER case300 (the `ieee300` builder). MATPOWER's case300 has no HVDC link (no DC
  line table, and no converter pair of equal and opposite injections among its generators and
  loads), so there is nothing to remove; the PNNL "noHVDC" files rebalance buses 119, 120 and 138
  of their PSS/E version instead, which is not reproduced. The study's zone-1 edit: the load of
  each of the 34 zone-1 motor buses (`MOTOR_BUSES_300`, the action buses of the PNNL task
  IEEE300_RL_loadShedding_zone1_continuous_LSTM_multipfcases_training_gp.json, all of them
  zone-1 load buses of 50 MW or more) moves behind a transformer onto bus 20000 + bus, with
  X = 0.01 p.u. on the load's own MVA (|S| at 1 p.u.; the PNNL transformers have about that
  size), split 40/40/20 % like the 39-bus case (PNNL: one load record per bus, the motor on
  it), with an ACMTBLU1 record on load ID 2 (40 % of the bus load) with the PNNL zone-1 CONs
  (`ACMTBLU1_300`: Vstall 0.7, CompPF 0.97, Vrst 0.9, ...); FIDVR appears with that share, so
  it was not raised. Observed buses,
  as the PNNL task's zone-1 observation (zone 1, above 60 kV, plus the low-voltage load buses):
  every zone-1 bus of the case above 60 kV (106; PNNL's zone 1 also holds 1190 and 1200, which
  MATPOWER puts in zone 2) and the 34 motor buses. Action buses: the 34 motor buses.
  Machines: one typical data set for every unit, the round-rotor machine of Kundur's two-area
  example (Power System Stability and Control, 1994, Example 12.6): Xd 1.8, Xq 1.7, X'd 0.3,
  X'q 0.55, X''d = X''q 0.25, Xl 0.2, T'do 8 s, T'qo 0.4 s, T''do 0.03 s, T''qo 0.05 s, H 6.5 s,
  D 0, Ra 0, saturation S(1.0) = 0.039, S(1.2) = 0.223 (Kundur's Asat = 0.015, Bsat = 9.6,
  psiT1 = 0.9 evaluated at 1.0 and 1.2 p.u. flux), all on the unit's MBASE.

Both cases
  MBASE: the level-1.0 power flow's |S| of the unit divided by 0.7, rounded up to 10 MVA, at
  least 20 MVA, so every unit runs at 70 % of its rating at load_level 1 (MATPOWER gives
  100 MVA for every unit); ZSOURCE = j X''d on MBASE. Machine data, MBASE and transformer sizes
  stay those of level 1 at every load_level.
  Reactive limits: the 39-bus case has none (as the PNNL 39-bus file: the power flow with
  MATPOWER's limits does not converge at load_level 0.5 or 1.3); the 300-bus case keeps
  MATPOWER's (as the PNNL 300-bus files keep theirs). No over-excitation limiter is modelled.
  Exciter: IEEET1 (IEEE 1968 type 1 DC exciter) with one typical set for every unit
  (`IEEET1_TYPICAL`: TR 0, KA 40, TA 0.02 s, KE 1, TE 0.8 s, KF 0.03, TF 1 s) and no exciter
  saturation; the ceiling VRMAX = -VRMIN = 8 p.u. is twice the largest field voltage at
  load_level 1 (the 39-bus unit at bus 34, Xd = 0.67 p.u. on 100 MVA, needs EFD = 4.0) and
  still 1.45 times it at load_level 1.4.
  Governors: TGOV1 with typical values (`TGOV1_TYPICAL`: 5 % droop, T1 0.5 s valve, reheat
  lead-lag T2/T3 = 3 s/10 s, VMAX 1.05, VMIN 0) on every unit that produces active power; the
  39-bus hydro unit at bus 30 gets HYGOV instead (`HYGOV_TYPICAL`: 5 % permanent, 30 %
  temporary droop, Tr 5 s, Tf 0.05 s, Tg 0.5 s, VELM 0.2, gate 0-1, Tw 1 s, At 1.2, qNL 0.08).
  The twelve 300-bus units with zero dispatch that are not the slack are synchronous condensers:
  they have no turbine and get no governor.
  load_level: scales every load (P and Q, all ZIP parts) and every generator's P dispatch by the
  same factor; the slack takes the change in losses. Allowed: [0.5, 1.4] for ieee39_fidvr (the
  valves stay below VMAX), [0.5, 1.0] for ieee300_fidvr (with MATPOWER's reactive limits the
  power flow stops converging near 1.05). The case name gets "_load<percent>" appended, e.g.
  "ieee39_fidvr_load110".
"""
from __future__ import annotations

import dataclasses
import functools
import math
import numpy as np

from jaxgrid.case import SLACK, Case, at_load_level, build_case, to_rows
from jaxgrid.cases.registry import register
from jaxgrid.cases.ieee import ieee39, ieee300, move_loads_behind_transformers
from jaxgrid.models.acmotor import Acmtblu1
from jaxgrid.models.base import DeviceModel
from jaxgrid.models.exciters import Ieeet1
from jaxgrid.models.governors import Hygov, Tgov1
from jaxgrid.models.machines import Genrou
from jaxgrid.powerflow import bus_loads, solve
from jaxgrid.records import DyrData, DyrRecord

# Allowed load_level per case (module docstring).
LOAD_LEVEL_RANGE = {"ieee39_fidvr": (0.5, 1.4), "ieee300_fidvr": (0.5, 1.0)}

# --------------------------------------------------------------------------- #
# Data (sources in the module docstring)
# --------------------------------------------------------------------------- #

OBSERVED_BUSES_39 = (4, 504, 7, 507, 8, 508, 18, 518)
ACTION_BUSES_39 = (504, 507, 518)
MOTOR_BUSES_39 = (504, 507, 518)
MOTOR_LOAD_ID = "2"  # the 40 % record of the 40/40/20 split carries the motor

# Original bus numbers of the 300-bus zone-1 motor loads; the loads move onto 20000 + bus.
MOTOR_BUSES_300 = (1, 2, 5, 6, 8, 9, 10, 11, 13, 14, 15, 17, 20, 21, 22, 27, 33, 37, 38, 44, 47,
                   49, 52, 53, 57, 59, 61, 63, 70, 71, 72, 73, 76, 77)
LOAD_BUS_OFFSET_300 = 20000
LOAD_XFMR_X_OWN_BASE = 0.01  # p.u. on the load's MVA
OBSERVED_ZONE_300 = 1
OBSERVED_MIN_KV_300 = 60.0

# The study's reward values (jaxgrid.env.EnvParams fields; PNNL task files
# IEEE39_RL_loadShedding_3motor_continuous.json and the 300-bus LSTM training file, whose
# recovery level 0.9 / 5 s is not used here: the built-in 300-bus case checks 0.95 at 4 s).
REWARD_39 = dict(c_voltage=260.0, c_shed=150.0, c_invalid=3.0, c_prefault=100.0,
                 unstable_penalty=1000.0, recovery_level=0.95, recovery_time=4.0,
                 action_low=-0.2, action_high=0.0)
REWARD_300 = dict(REWARD_39, c_voltage=30.0, unstable_penalty=10000.0)

# Fault sets, (fault buses, durations in s), faults at 1.0 s. 39-bus: the PNNL training buses
# and the paper's 120 test tasks. 300-bus: the training file's buses plus bus 26, and as test
# buses those of the testing file plus bus 26 (34 zone-1 buses).
ZONE1_TEST_BUSES_300 = (3, 5, 12, 2, 8, 15, 17, 23, 1, 4, 6, 7, 9, 10, 11, 13, 14, 16, 19, 20,
                        21, 22, 25, 87, 102, 89, 125, 160, 320, 150, 123, 131, 130, 26)
TASK_SETS_39 = {"train": ((4, 15, 21), (0.0, 0.05, 0.08)),
                "test": (tuple(range(1, 31)), (0.02, 0.05, 0.08, 0.1))}
TASK_SETS_300 = {"train": ((2, 3, 5, 8, 12, 15, 17, 23, 26), (0.0, 0.05, 0.08)),
                 "test": (ZONE1_TEST_BUSES_300, (0.05, 0.06, 0.07, 0.08, 0.1))}

# Pai (1989) New England machine data, p.u. on 100 MVA, by bus:
#        H      Xl      Xd      X'd     T'do   Xq      X'q     T'qo
PAI_39 = {
    30: (42.0, 0.0125, 0.1000, 0.0310, 10.20, 0.0690, 0.0080, 0.00),
    31: (30.3, 0.0350, 0.2950, 0.0697, 6.56, 0.2820, 0.1700, 1.50),
    32: (35.8, 0.0304, 0.2495, 0.0531, 5.70, 0.2370, 0.0876, 1.50),
    33: (28.6, 0.0295, 0.2620, 0.0436, 5.69, 0.2580, 0.1660, 1.50),
    34: (26.0, 0.0540, 0.6700, 0.1320, 5.40, 0.6200, 0.1660, 0.44),
    35: (34.8, 0.0224, 0.2540, 0.0500, 7.30, 0.2410, 0.0814, 0.40),
    36: (26.4, 0.0322, 0.2950, 0.0490, 5.66, 0.2920, 0.1860, 1.50),
    37: (24.3, 0.0280, 0.2900, 0.0570, 6.70, 0.2800, 0.0911, 0.41),
    38: (34.5, 0.0298, 0.2106, 0.0570, 4.79, 0.2050, 0.0587, 1.96),
    39: (500.0, 0.0030, 0.0200, 0.0060, 7.00, 0.0190, 0.0080, 0.70),
}
PAI_BASE_MVA = 100.0
HYDRO_39 = (30,)
SUBTRANSIENT_RATIO = 0.8  # X''d / X'd where the data set has no subtransient values
T_PPDO, T_PPQO = 0.03, 0.05  # s

# Kundur (1994) Example 12.6 machine, p.u. on MBASE (GENROU CON names).
KUNDUR_GENROU = dict(tpdo=8.0, tppdo=0.03, tpqo=0.4, tppqo=0.05, h=6.5, d=0.0, xd=1.8, xq=1.7,
                     xpd=0.3, xpq=0.55, xppd=0.25, xl=0.2, s1=0.039, s12=0.223)

# Exciter and governors (CON names of jaxgrid.models).
IEEET1_TYPICAL = dict(tr=0.0, ka=40.0, ta=0.02, vrmax=8.0, vrmin=-8.0, ke=1.0, te=0.8,
                      kf=0.03, tf=1.0, switch=0.0, e1=0.0, se1=0.0, e2=0.0, se2=0.0)
TGOV1_TYPICAL = dict(r=0.05, t1=0.5, vmax=1.05, vmin=0.0, t2=3.0, t3=10.0, dt=0.0)
HYGOV_TYPICAL = dict(r=0.05, r_temp=0.3, tr=5.0, tf=0.05, tg=0.5, velm=0.2, gmax=1.0, gmin=0.0,
                     tw=1.0, at=1.2, dturb=0.0, qnl=0.08)

MBASE_LOADING = 0.7  # |S| / MBASE of every unit at load_level 1
MBASE_STEP, MBASE_MIN = 10.0, 20.0  # MVA
NO_Q_LIMIT = 99.99  # p.u. system base (9999 Mvar), as "no limit" in PSS/E files

# ACMTBLU1 USRLOD header and the two cases' CONs (names as in shared/specs/acmtblu1.md §2).
# NC = 36: the 36th CON (GridPACK's extension) is the motor's share of its load record, 1.0:
# the whole record, as these cases were built (`jaxgrid.models.acmotor`, share_mode).
ACMTBLU1_HEADER = (12, 1, 0, 36, 9, 29, 16)  # IC, IT, NI, NC, NS, NV, NX
WHOLE_RECORD = 1.0
ACMTBLU1_39 = dict(
    tstall=0.033, trst=0.40, tv=0.02, tf=0.05, complf=0.0, comppf=0.98, vstall=0.5, rstall=0.124,
    xstall=0.114, lfadj=0.3, kp1=0.0, np1=1.0, kq1=6.0, nq1=2.0, kp2=12.0, np2=3.2, kq2=11.0,
    nq2=2.5, vbrk=0.86, frst=0.20, vrst=0.95, cmpkpf=1.0, cmpkqf=-3.3, vc1off=0.5, vc2off=0.4,
    vc1on=0.65, vc2on=0.55, tth=15.0, th1t=1.0, th2t=2.9, fuvr=0.0, uvtr1=0.5, ttr1=0.02,
    uvtr2=0.90, ttr2=5.0)
ACMTBLU1_300 = dict(ACMTBLU1_39, comppf=0.97, vstall=0.7, vrst=0.9, vc1off=0.45, vc2off=0.35,
                    vc1on=0.5, vc2on=0.4, tth=10.0, th1t=1.3, th2t=4.3, uvtr1=0.8, ttr1=0.2)


# --------------------------------------------------------------------------- #
# The study case
# --------------------------------------------------------------------------- #

@dataclasses.dataclass(frozen=True)
class StudyCase:
    """A network with its dynamic models and the load-shedding task's buses.

    Attributes:
      name: case name with the load level, e.g. "ieee39_fidvr_load100".
      case: the network at this operating point.
      dyr: dynamic model records (source "jaxgrid.cases.<name>", line = record index).
      observed_buses: bus numbers whose voltage the task observes.
      action_buses: bus numbers whose load the task can shed.
      motor_buses: bus numbers with an ACMTBLU1 motor load.
      dt: integration step of the study, s.
      sweeps: network fixed-point sweeps per solution. dt and sweeps are the fastest pair
        accurate to p99 |ΔV| <= 1e-3 p.u. against a float64 1-ms 4-sweep reference
        (`experiments.diagnostics.step_accuracy`, docs/studies.md "Step size by accuracy").
      load_level: factor on every load and generator dispatch (1 = the base case).
      description: one paragraph on how the case was built.
      reward: the study's `jaxgrid.env.EnvParams` values by field name.
      task_sets: {"train" | "test": (fault buses, fault durations in s)}, faults at 1.0 s.
    """

    name: str
    case: Case
    dyr: DyrData
    observed_buses: tuple[int, ...]
    action_buses: tuple[int, ...]
    motor_buses: tuple[int, ...]
    dt: float
    sweeps: int
    load_level: float
    description: str
    reward: dict
    task_sets: dict


@register("ieee39_fidvr")
def ieee39_fidvr(load_level: float = 1.0) -> StudyCase:
    """IEEE 39-bus FIDVR study at `load_level`: A/C motors at 504/507/518, GENROU + IEEET1 +
    TGOV1/HYGOV (StudyCase.description)."""
    level = _check_level(load_level, "ieee39_fidvr")
    base, mbase = _ieee39_base()
    case = at_load_level(base, level, f"ieee39_fidvr_load{100 * level:g}",
                         "jaxgrid.cases.ieee39_fidvr")
    gen = case.generators
    buses = [int(case.buses.number[b]) for b in gen.bus]
    records = []
    for k, bus in enumerate(buses):
        gen_id = gen.gen_id[k]
        records.append(("GENROU", bus, gen_id, _genrou_39(bus, mbase[k])))
        records.append(("IEEET1", bus, gen_id, _cons(Ieeet1, IEEET1_TYPICAL)))
        governor = (Hygov, HYGOV_TYPICAL) if bus in HYDRO_39 else (Tgov1, TGOV1_TYPICAL)
        records.append((governor[0].name, bus, gen_id, _cons(*governor)))
    records += [("ACMTBLU1", bus, MOTOR_LOAD_ID,
                 _cons(Acmtblu1, ACMTBLU1_39) + (WHOLE_RECORD,))
                for bus in MOTOR_BUSES_39]
    return StudyCase(
        name=case.name, case=case, dyr=_dyr("ieee39_fidvr", records),
        observed_buses=OBSERVED_BUSES_39, action_buses=ACTION_BUSES_39,
        motor_buses=MOTOR_BUSES_39, dt=0.002, sweeps=1, load_level=level, reward=REWARD_39,
        task_sets=TASK_SETS_39,
        description=("IEEE 39-bus (MATPOWER case39) with the PNNL study's load buses 504/507/508/"
                     "518 behind transformers, ACMTBLU1 A/C motors on 40 % of the load at 504, "
                     "507 and 518, Pai's machine data as GENROU, IEEET1 exciters, TGOV1 "
                     "governors (HYGOV at bus 30)."))


@register("ieee300_fidvr")
def ieee300_fidvr(load_level: float = 1.0) -> StudyCase:
    """IEEE 300-bus FIDVR study at `load_level`: zone-1 loads on 200xx buses with A/C motors,
    GENROU + IEEET1 + TGOV1 (StudyCase.description)."""
    level = _check_level(load_level, "ieee300_fidvr")
    base, observed = _ieee300_base()
    case = at_load_level(base, level, f"ieee300_fidvr_load{100 * level:g}",
                         "jaxgrid.cases.ieee300_fidvr")
    gen = case.generators
    motor_buses = tuple(LOAD_BUS_OFFSET_300 + b for b in MOTOR_BUSES_300)
    condenser = (gen.pg == 0) & (case.buses.kind[gen.bus] != SLACK)
    records = []
    for k, bus in enumerate(int(case.buses.number[b]) for b in gen.bus):
        gen_id = gen.gen_id[k]
        records.append(("GENROU", bus, gen_id, _cons(Genrou, KUNDUR_GENROU)))
        records.append(("IEEET1", bus, gen_id, _cons(Ieeet1, IEEET1_TYPICAL)))
        if not condenser[k]:
            records.append(("TGOV1", bus, gen_id, _cons(Tgov1, TGOV1_TYPICAL)))
    records += [("ACMTBLU1", bus, MOTOR_LOAD_ID,
                 _cons(Acmtblu1, ACMTBLU1_300) + (WHOLE_RECORD,))
                for bus in motor_buses]
    return StudyCase(
        name=case.name, case=case, dyr=_dyr("ieee300_fidvr", records),
        observed_buses=observed, action_buses=motor_buses, motor_buses=motor_buses, dt=0.005,
        sweeps=1, load_level=level, reward=REWARD_300, task_sets=TASK_SETS_300,
        description=("IEEE 300-bus (MATPOWER case300) with the loads of the 34 zone-1 motor buses "
                     "behind transformers on buses 200xx, ACMTBLU1 A/C motors on 40 % of each, "
                     "Kundur's typical machine as GENROU on every unit, IEEET1 exciters, TGOV1 "
                     "governors; observed: zone-1 buses above 60 kV and the motor buses."))


# --------------------------------------------------------------------------- #
# Networks at load level 1 (cached)
# --------------------------------------------------------------------------- #

@functools.lru_cache(maxsize=None)
def _ieee39_base() -> tuple[Case, np.ndarray]:
    """(network at level 1 with machine bases and no reactive limits, MBASE per unit)."""
    return _with_machine_bases(_without_q_limits(ieee39()), _subtransient_39)


@functools.lru_cache(maxsize=None)
def _ieee300_base() -> tuple[Case, tuple[int, ...]]:
    """(network at level 1 with machine bases, observed buses)."""
    case = ieee300()
    number = case.buses.number
    zone1_hv = tuple(int(b) for b, z, kv in zip(number, case.buses.zone, case.buses.base_kv)
                     if z == OBSERVED_ZONE_300 and kv > OBSERVED_MIN_KV_300)
    load_mva = np.abs(sum(bus_loads(case))) * case.base_mva
    x = dict(zip(MOTOR_BUSES_300, LOAD_XFMR_X_OWN_BASE * case.base_mva
                 / load_mva[case.bus_index(MOTOR_BUSES_300)]))
    case = move_loads_behind_transformers(case, MOTOR_BUSES_300, offset=LOAD_BUS_OFFSET_300, x=x)
    case, _ = _with_machine_bases(case, lambda bus, m: KUNDUR_GENROU["xppd"])
    observed = zone1_hv + tuple(LOAD_BUS_OFFSET_300 + b for b in MOTOR_BUSES_300)
    return case, observed


def _without_q_limits(case: Case) -> Case:
    rows = to_rows(case)
    for g in rows["generators"]:
        g.update(qmax=NO_Q_LIMIT, qmin=-NO_Q_LIMIT)
    return build_case(**dict(rows, notes=(*case.notes, "generator reactive limits removed")))


def _with_machine_bases(case: Case, xppd) -> tuple[Case, np.ndarray]:
    """The case with MBASE from its power flow (module docstring) and ZSOURCE = j X''d.

    `xppd(bus, mbase)` gives X''d on MBASE. Returns (case, MBASE per generator, MVA).
    """
    pf = solve(case)
    s = case.base_mva * np.hypot(pf.pg, pf.qg)
    mbase = np.maximum(MBASE_MIN, MBASE_STEP * np.ceil(s / MBASE_LOADING / MBASE_STEP))
    mbase.setflags(write=False)  # cached with the case
    rows = to_rows(case)
    for g, m in zip(rows["generators"], mbase):
        g.update(mbase=float(m), zr=0.0, zx=float(xppd(int(g["bus"]), float(m))))
    return build_case(**rows), mbase


def _check_level(load_level, name: str) -> float:
    lo, hi = LOAD_LEVEL_RANGE[name]
    ok = (isinstance(load_level, (int, float, np.integer, np.floating))
          and not isinstance(load_level, bool) and math.isfinite(load_level))
    if not ok or not lo <= load_level <= hi:
        raise ValueError(f"{name}: load_level = {load_level!r} ({type(load_level).__name__}): "
                         f"must be a number in [{lo}, {hi}] (factor on every load and "
                         "generator dispatch)")
    return float(load_level)


# --------------------------------------------------------------------------- #
# Dynamic records
# --------------------------------------------------------------------------- #

def _cons(model: type[DeviceModel], values: dict[str, float]) -> tuple[float, ...]:
    """CON tuple in the model's PSS/E order from values keyed by CON name."""
    names = [c.name for c in model.cons]
    if set(values) != set(names):
        raise KeyError(f"{model.name}: values for {sorted(values)} but CONs are {names}")
    return tuple(float(values[n]) for n in names)


def _subtransient_39(bus: int, mbase: float) -> float:
    """X''d on MBASE of the 39-bus unit at `bus` (Pai's X'd times SUBTRANSIENT_RATIO)."""
    return SUBTRANSIENT_RATIO * PAI_39[bus][3] * mbase / PAI_BASE_MVA


def _genrou_39(bus: int, mbase: float) -> tuple[float, ...]:
    """GENROU CONs on MBASE from Pai's data on 100 MVA (module docstring)."""
    h, xl, xd, xpd, tpdo, xq, xpq, tpqo = PAI_39[bus]
    if tpqo == 0:  # no q-axis transient winding (bus 30)
        xpq, tpqo = xq, 1.0
    k = mbase / PAI_BASE_MVA
    return _cons(Genrou, dict(
        tpdo=tpdo, tppdo=T_PPDO, tpqo=tpqo, tppqo=T_PPQO, h=h / k, d=0.0, xd=xd * k, xq=xq * k,
        xpd=xpd * k, xpq=xpq * k, xppd=SUBTRANSIENT_RATIO * xpd * k, xl=xl * k, s1=0.0, s12=0.0))


def _dyr(name: str, records) -> DyrData:
    """DyrData from (model, bus, device id, cons); ACMTBLU1 as a USRLOD record."""
    source = f"jaxgrid.cases.{name}"
    out = []
    for line, (model, bus, device_id, cons) in enumerate(records, start=1):
        user = model == "ACMTBLU1"
        out.append(DyrRecord(model=model, bus=int(bus), device_id=str(device_id), cons=cons,
                             icons=(), header=ACMTBLU1_HEADER if user else (),
                             record_type="USRLOD" if user else model, line=line, source=source))
    return DyrData(source=source, records=tuple(out), unsupported={})
