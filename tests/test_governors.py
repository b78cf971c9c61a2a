"""Turbine-governor models (`jaxgrid.models.governors`, spec §9-§13).

1. Steady initialisation on real DYR data (IEEE 39-bus, ACTIVSg2000, ANDES's Kundur case),
   also with every bypassable time constant set to zero in half of the units.
2. Known answers: droop and static gains after a constant speed deviation settles,
   non-windup and rate limits, the GAST load limit.
3. Bad data raise a ModelError naming file:line and the CON.

Integration is explicit Euler with the non-windup clip after every step, jitted once per
model; the settled values below are exact steady states of the equations.
"""
from __future__ import annotations

import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import SHARED_CASES, andes_cases_dir
from jaxgrid.io.dyr import read_dyr
from jaxgrid.models.base import ModelError
from jaxgrid.models.governors import (GOVERNORS, WIDEN_MARGIN, Gast, Ggov1, GovernorPorts,
                                      GovernorStart, Hygov, Ieeeg1, Ieesgo, Tgov1, Wsieg1)
from jaxgrid.records import DyrRecord

IEEE39_DYR = SHARED_CASES / "ieee39" / "IEEE39bus_3AC.dyr"
GRIDPACK_DYR = SHARED_CASES / "ieee39" / "IEEE39bus_3AC_exdc1_gridpack.dyr"  # WSIEG1
ACTIVSG_DYR = SHARED_CASES / "activsg2000" / "ACTIVSg2000_dyn_acmotor_zone3_v1.dyr"

STEADY_TOL = 1e-9   # float64 residual of an exact steady state (values of order 1)
SETTLED_TOL = 1e-7  # after integrating many slowest time constants


@pytest.fixture(autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module")
def records(tmp_path_factory) -> dict[str, dict[str, tuple]]:
    """{source: {model: DYR records}} for the three reference files (each read once)."""
    kundur = [line for line in (andes_cases_dir() / "kundur" / "kundur_full.dyr")
              .read_text().splitlines() if "Toggle" not in line]
    kundur_path = tmp_path_factory.mktemp("kundur") / "kundur_full.dyr"
    kundur_path.write_text("\n".join(kundur) + "\n")
    out = {}
    for source, path in (("ieee39", IEEE39_DYR), ("activsg", ACTIVSG_DYR), ("kundur", kundur_path),
                         ("gridpack39", GRIDPACK_DYR)):
        data = read_dyr(path, supported=None)
        out[source] = {name: data.by_model(name) for name in GOVERNORS}
    return out


def ports(dw) -> GovernorPorts:
    """Ports at speed deviation dw with the electrical power 0 (read by GGOV1 only)."""
    dw = jnp.asarray(dw, dtype=float)
    return GovernorPorts(dw=dw, pe=jnp.zeros_like(dw))


def start(pm0) -> GovernorStart:
    """A start at mechanical power pm0 (p.u.), the same electrical power, MBASE 100 MVA."""
    pm0 = jnp.asarray(pm0, dtype=float)
    return GovernorStart(pm=pm0, pe=pm0, mbase=jnp.full_like(pm0, 100.0))


def params(model, recs, **changes):
    """Prepared params of `recs` with CONs in `changes` overwritten (scalars or arrays)."""
    p = model.read(recs)
    p = {k: np.broadcast_to(np.asarray(changes.get(k, v), dtype=float), v.shape).copy()
         for k, v in p.items()}
    return model.prepare(p)


def with_bypassed_half(model, p: dict) -> dict:
    """Each unit twice: as given, and with every time constant that may be zero set to 0."""
    zero_ok = {c.name for c in model.cons if c.unit == "s" and not c.positive}
    raw = {c.name: p[c.name] for c in model.cons}
    bypassed = {k: np.zeros_like(v) if k in zero_ok else v for k, v in raw.items()}
    return model.prepare({k: np.concatenate([raw[k], bypassed[k]]) for k in raw})


def simulate(model, p, x, dw, t_end: float, dt: float):
    """States after t_end s of explicit Euler at constant Δω, clipped to `limits` each step."""
    limits = model.limits(p)

    @jax.jit
    def run(p, x, dw):
        def step(_, x):
            _, dx = model.rates(p, x, ports(dw))
            x = {k: v + dt * dx[k] for k, v in x.items()}
            return {k: jnp.clip(v, *limits[k]) if k in limits else v for k, v in x.items()}
        return jax.lax.fori_loop(0, round(t_end / dt), step, x)

    return run(p, x, jnp.broadcast_to(jnp.asarray(dw, dtype=float), x[model.states[0]].shape))


# --------------------------------------------------------------------------- #
# 1. Initialisation on real data
# --------------------------------------------------------------------------- #

STEADY_CASES = [("TGOV1", "ieee39"), ("IEEEG1", "ieee39"), ("GAST", "ieee39"),
                ("IEESGO", "ieee39"), ("HYGOV", "activsg"), ("TGOV1", "kundur"),
                ("WSIEG1", "gridpack39")]


@pytest.mark.parametrize("bypass", [False, True], ids=["as-read", "half-bypassed"])
@pytest.mark.parametrize("name,source", STEADY_CASES)
def test_init_is_steady(records, name, source, bypass):
    model = GOVERNORS[name]
    recs = records[source][name]
    assert recs, f"no {name} records in {source}"
    p = params(model, recs)
    if bypass:
        p = with_bypassed_half(model, p)
    n = len(recs) * (2 if bypass else 1)
    pm0 = jnp.linspace(0.5, 0.8, n)  # inside every unit's limits in these files
    p, x, *_ = model.init(p, start(pm0))
    assert set(x) == set(model.states), f"{name}: init states {sorted(x)} != {model.states}"
    bad = {k: np.flatnonzero(v) for k, v in model.init_violations(p, x).items() if np.any(v)}
    assert not bad, f"{name} ({source}): init outside limits {bad}"
    pm, dx = model.rates(p, x, ports(jnp.zeros(n)))
    for state, d in dx.items():
        assert float(jnp.max(jnp.abs(d))) < STEADY_TOL, f"{name} ({source}) d{state}/dt = {d}"
    assert float(jnp.max(jnp.abs(pm - pm0))) < STEADY_TOL, f"{name} ({source}): Pm {pm} != {pm0}"


@pytest.mark.parametrize("name,source", STEADY_CASES[:5] + STEADY_CASES[6:])
def test_dynamics_jit_and_gradient(records, name, source):
    model = GOVERNORS[name]
    p = with_bypassed_half(model, params(model, records[source][name]))
    p, x, *_ = model.init(p, start(jnp.full(len(p[model.cons[0].name]), 0.7)))
    total_pm = jax.jit(lambda p, x, dw: jnp.sum(model.rates(p, x, ports(dw))[0]))
    dw = jnp.full(x[model.states[0]].shape, -0.002)
    grads = jax.grad(total_pm, argnums=(0, 1, 2))(p, x, dw)
    for leaf in jax.tree_util.tree_leaves(grads):
        assert bool(jnp.all(jnp.isfinite(leaf))), f"{name}: non-finite gradient"


def test_gast_init_above_at_is_flagged(records):
    # 39-bus GAST: AT = 0.9; VMAX raised to 1.2 so that only the load limit is violated.
    p = params(Gast, records["ieee39"]["GAST"], vmax=1.2)
    p, x, *_ = Gast.init(p, start(jnp.array([0.95])))
    flags = {k: bool(v[0]) for k, v in Gast.init_violations(p, x).items()}
    assert flags == {"x1": False, "x3": True}, flags


def test_ieeeg1_and_hygov_init_violations(records):
    p = params(Ieeeg1, records["ieee39"]["IEEEG1"][:1])  # PMIN = 0.4, K1 + K3 + K5 + K7 = 1
    p, x, *_ = Ieeeg1.init(p, start(jnp.array([0.3])))
    assert bool(Ieeeg1.init_violations(p, x)["pgv"][0]), "Pgv0 = 0.3 < PMIN = 0.4 not flagged"
    p = params(Hygov, records["activsg"]["HYGOV"][:1])  # GMAX = 1
    p, x, *_ = Hygov.init(p, start(jnp.array([2.0])))  # q0 = 2/At + qNL > 1
    assert bool(Hygov.init_violations(p, x)["g"][0]), "g0 > GMAX not flagged"


def test_ieeeg1_notes_warn_without_raising(records):
    recs = records["ieee39"]["IEEEG1"][:1]
    p = params(Ieeeg1, recs, k7=0.4, k8=0.1)  # K1..K8 = 0.27 + 0.25 + 0.4 + 0.1 = 1.02
    notes = Ieeeg1.notes(p)
    assert any("= 1.02, not 1" in s for s in notes), notes
    assert any("K2 + K4 + K6 + K8 = 0.1" in s for s in notes), notes
    assert Ieeeg1.notes(params(Ieeeg1, recs)) == []


# --------------------------------------------------------------------------- #
# 2. Behaviour with hand-derived answers
# --------------------------------------------------------------------------- #

def test_tgov1_droop_settles(records):
    # Kundur TGOV1: R = 0.05, T1 = 0.49, T2 = 2.1, T3 = 7 (Dt set to 0.5 here). In steady
    # state x1 = x2 = (Pref − Δω)/R = Pm0 − Δω/R, so Pm = Pm0 − Δω/R − Dt·Δω.
    p = params(Tgov1, records["kundur"]["TGOV1"], dt=0.5)
    pm0, dw = 0.7, 0.001
    p, x, *_ = Tgov1.init(p, start(jnp.full(4, pm0)))
    x = simulate(Tgov1, p, x, dw, t_end=200.0, dt=0.01)  # 28 T3: transient < 1e-12
    pm, _ = Tgov1.rates(p, x, ports(jnp.full(4, dw)))
    expected = pm0 - dw / 0.05 - 0.5 * dw
    assert np.allclose(pm, expected, rtol=0, atol=SETTLED_TOL), (pm, expected)


def test_tgov1_vmax_is_non_windup(records):
    # Underspeed Δω = −0.05 asks x1 → Pm0 + 1; VMAX = 0.9 stops it exactly there. Back at
    # Δω = 0 the valve leaves VMAX at once (a windup state would stay above it).
    p = params(Tgov1, records["kundur"]["TGOV1"][:1], vmax=0.9)
    p, x, *_ = Tgov1.init(p, start(jnp.array([0.7])))
    x = simulate(Tgov1, p, x, -0.05, t_end=5.0, dt=0.01)
    assert float(x["x1"][0]) == 0.9, x["x1"]
    _, dx = Tgov1.rates(p, x, ports(jnp.array([-0.05])))
    assert float(dx["x1"][0]) == 0.0, "derivative not frozen at VMAX"
    _, dx = Tgov1.rates(p, x, ports(jnp.array([0.0])))
    assert float(dx["x1"][0]) == pytest.approx((0.7 - 0.9) / 0.49), dx["x1"]


def test_ieeeg1_valve_rate_limits(records):
    # 39-bus unit, bus 33: K = 20, T1 = T2 = 0, T3 = 0.1, Uo = 0.1, Uc = −0.5, PMIN = 0.4.
    # Valve speed (P0 − K·Δω − Pgv)/T3 = ∓2 p.u./s at the step, clipped to Uc or Uo; it stays
    # clipped while the gap exceeds Uo·T3 = 0.01 (opening) or |Uc|·T3 = 0.05 (closing).
    p = params(Ieeeg1, records["ieee39"]["IEEEG1"][:1])
    p, x0, *_ = Ieeeg1.init(p, start(jnp.array([0.5])))
    _, dx = Ieeeg1.rates(p, x0, ports(jnp.array([-0.01])))
    assert float(dx["pgv"][0]) == 0.1, "opening rate is not Uo"
    _, dx = Ieeeg1.rates(p, x0, ports(jnp.array([0.01])))
    assert float(dx["pgv"][0]) == -0.5, "closing rate is not Uc"
    # Opening: the gap 0.2 shrinks at Uo for 1.9 s, so after 1 s Pgv = 0.5 + Uo·1 exactly.
    x = simulate(Ieeeg1, p, x0, -0.01, t_end=1.0, dt=0.001)
    assert float(x["pgv"][0]) == pytest.approx(0.6, abs=1e-12)
    # Closing towards P0 − 0.2 = 0.3 < PMIN: stops exactly at PMIN = 0.4 (after 0.2 s at Uc).
    x = simulate(Ieeeg1, p, x0, 0.01, t_end=1.0, dt=0.001)
    assert float(x["pgv"][0]) == 0.4, x["pgv"]
    _, dx = Ieeeg1.rates(p, x, ports(jnp.array([0.01])))
    assert float(dx["pgv"][0]) == 0.0, "valve derivative not frozen at PMIN"


def test_ieeeg1_bypassed_turbine_follows_valve(records):
    # T4..T7 = 0: every stage passes its input, so Pm = (K1 + K3 + K5 + K7)·Pgv at once.
    p = params(Ieeeg1, records["ieee39"]["IEEEG1"][:1], t4=0, t5=0, t6=0, t7=0)
    p, x, *_ = Ieeeg1.init(p, start(jnp.array([0.6])))
    x = dict(x, pgv=jnp.array([0.65]))
    pm, dx = Ieeeg1.rates(p, x, ports(jnp.array([0.0])))
    assert float(pm[0]) == pytest.approx(0.65, abs=1e-15)
    assert all(float(dx[s][0]) == 0.0 for s in ("y4", "y5", "y6", "y7")), dx


def test_ieesgo_static_gain_and_lead(records):
    # 39-bus IEESGO: K1 = 14.3, PMIN = 0.5. Steady state: y5 = K2·y4, y6 = K3·y5, so
    # Pm = y4 = Pgv = P0 − K1·Δω (inside [PMIN, PMAX]).
    p = params(Ieesgo, records["ieee39"]["IEESGO"])
    p, x, *_ = Ieesgo.init(p, start(jnp.full(2, 0.8)))
    x = simulate(Ieesgo, p, x, 0.001, t_end=60.0, dt=0.002)  # slowest T5 = 3 s
    pm, _ = Ieesgo.rates(p, x, ports(jnp.full(2, 0.001)))
    assert np.allclose(pm, 0.8 - 14.3 * 0.001, rtol=0, atol=SETTLED_TOL), pm
    # T1 = 0 with T2 = 1, T3 = 0.5 and no turbine lags: the lead pairs with T3, so a speed
    # step gives K1·(T2/T3)·Δω at once; with T1 = T3 = 0 the filter is the static gain K1.
    p = params(Ieesgo, records["ieee39"]["IEESGO"], t1=0, t2=1.0, t3=[0.5, 0.0],
               t4=0, t5=0, t6=0)
    p, x, *_ = Ieesgo.init(p, start(jnp.full(2, 0.8)))
    pm, _ = Ieesgo.rates(p, x, ports(jnp.full(2, 0.001)))
    assert np.allclose(pm, [0.8 - 14.3 * 2 * 0.001, 0.8 - 14.3 * 0.001], rtol=0, atol=1e-14), pm


def test_gast_load_limit(records):
    # 39-bus GAST: R = 0.05, AT = 0.9, KT = 2 (VMAX raised to 1.2). Underspeed Δω = −0.01
    # demands Pm0 + 0.2 = 1.0; the limit AT + KT·(AT − x3) = x3 settles at x3 = AT.
    p = params(Gast, records["ieee39"]["GAST"], vmax=1.2)
    p, x, *_ = Gast.init(p, start(jnp.array([0.8])))
    x = simulate(Gast, p, x, -0.01, t_end=60.0, dt=0.002)
    pm, _ = Gast.rates(p, x, ports(jnp.array([-0.01])))
    assert float(pm[0]) == pytest.approx(0.9, abs=SETTLED_TOL)


def test_hygov_droop_settles(records):
    # Settled: x1 = 0, e = nref − Δω − R·c = 0 → c = g = q = c0 − Δω/R, head h = 1, and
    # Pm = At·(q − qNL) − Dturb·Δω·g = Pm0 − At·Δω/R − Dturb·Δω·g.
    recs = records["activsg"]["HYGOV"][:3]
    p = params(Hygov, recs, dturb=0.5)
    pm0, dw = 0.6, 0.0005
    p, x, *_ = Hygov.init(p, start(jnp.full(3, pm0)))
    x = simulate(Hygov, p, x, dw, t_end=2000.0, dt=0.01)  # slowest mode r·Tr/R ≈ 74 s
    pm, _ = Hygov.rates(p, x, ports(jnp.full(3, dw)))
    g = p["nref"] / p["r"] - dw / p["r"]
    expected = pm0 - p["at"] * dw / p["r"] - 0.5 * dw * g
    assert np.allclose(x["g"], g, rtol=0, atol=SETTLED_TOL), (x["g"], g)
    assert np.allclose(pm, expected, rtol=0, atol=SETTLED_TOL), (pm, expected)


def test_hygov_velm_and_gate_limits(records):
    # A large filtered error asks the integrator for x1/(r·Tr) >> VELM: it moves at VELM,
    # and not at all once at GMAX.
    p = params(Hygov, records["activsg"]["HYGOV"][:1])
    p, x, *_ = Hygov.init(p, start(jnp.array([0.5])))
    _, dx = Hygov.rates(p, dict(x, x1=jnp.array([1.0])), ports(jnp.array([0.0])))
    assert float(dx["xi"][0]) == float(p["velm"][0]), dx["xi"]
    _, dx = Hygov.rates(p, dict(x, x1=jnp.array([-1.0])), ports(jnp.array([0.0])))
    assert float(dx["xi"][0]) == -float(p["velm"][0]), dx["xi"]
    at_max = dict(x, x1=jnp.array([1.0]), xi=p["gmax"])
    _, dx = Hygov.rates(p, at_max, ports(jnp.array([0.0])))
    assert float(dx["xi"][0]) == 0.0, "integrator not frozen at GMAX"
    pm, dx = Hygov.rates(p, dict(x, g=jnp.array([0.0])), ports(jnp.array([0.0])))
    assert bool(jnp.isfinite(pm[0]) & jnp.isfinite(dx["q"][0])), "closed gate gives inf/nan"


# --------------------------------------------------------------------------- #
# 3. Errors in the data
# --------------------------------------------------------------------------- #

def read_error(model, tmp_path: Path, text: str) -> str:
    path = tmp_path / "gov.dyr"
    path.write_text(text)
    data = read_dyr(path, supported=None)
    with pytest.raises(ModelError) as err:
        model.read(data.by_model(model.name))
    message = str(err.value)
    assert message.startswith(f"{path}:"), message
    return message


TGOV1_OK = "// header comment\n1 'TGOV1' 1  0.05 0.49 33.0 0.4\n    2.1 7.0 0.0 /\n"


def test_errors_control_reads(tmp_path):
    path = tmp_path / "ok.dyr"
    path.write_text(TGOV1_OK)
    p = Tgov1.read(read_dyr(path, supported=None).by_model("TGOV1"))
    assert float(p["t3"][0]) == 7.0


def test_tgov1_zero_t3_is_rejected(tmp_path):
    bad_record = "2 'TGOV1' 1 0.05 0.49 33 0.4 2.1 0.0 0.0 /\n"
    message = read_error(Tgov1, tmp_path, TGOV1_OK + bad_record)
    assert re.search(r":4: TGOV1 at bus 2 .*CON\(6\) T3 = 0 s: must be > 0", message), message


def test_tgov1_negative_r_is_rejected(tmp_path):
    message = read_error(Tgov1, tmp_path, TGOV1_OK.replace("0.05", "-0.05"))
    assert re.search(r":2: TGOV1 at bus 1 .*CON\(1\) R = -0.05 p.u.: must be > 0", message), message


def test_ieeeg1_second_machine_is_rejected(tmp_path):
    lines = IEEE39_DYR.read_text().splitlines()
    assert lines[38].startswith("33 'IEEEG1'  1   0              0"), lines[38]
    lines[38] = lines[38].replace("1   0              0", "1   32             1", 1)
    message = read_error(Ieeeg1, tmp_path, "\n".join(lines) + "\n")
    assert re.search(r":39: IEEEG1 at bus 33 .*JBUS = 32 .*second \(low-pressure\) machine",
                     message), message


@pytest.mark.parametrize("model", list(GOVERNORS.values()), ids=list(GOVERNORS))
def test_con_tables_are_complete(model):
    counts = {"TGOV1": 7, "IEEEG1": 20, "WSIEG1": 34, "GAST": 9, "IEESGO": 11, "HYGOV": 12,
              "GGOV1": 33}
    names = [c.name for c in model.cons]
    assert len(names) == counts[model.name] and len(set(names)) == len(names), names
    assert all(c.unit and c.info for c in model.cons), model.name
    assert model.states, model.name


def test_wsieg1_droop_settles(records):
    """PNNL GridPACK 39-bus WSIEG1 (K = 25, T1 = T2 = 0, T3 = 0.1, T4 = 0.3, K1 = 1): a
    speed 0.2 % low opens the valve by K·0.002 p.u., reached as Pm after the T4 lag."""
    p = params(Wsieg1, records["gridpack39"]["WSIEG1"][:1])
    p, x, *_ = Wsieg1.init(p, start(jnp.array([0.6])))
    x = simulate(Wsieg1, p, x, -0.002, 10.0, 1e-3)
    pm, _ = Wsieg1.rates(p, x, ports(jnp.full(1, -0.002)))
    assert float(pm[0]) == pytest.approx(0.6 + 25.0 * 0.002, abs=SETTLED_TOL)


def test_wsieg1_limits_widen_at_init_as_gridpack(records):
    """A valve that starts above PMAX (1.01, unit 31 of the PNNL data at its RAW MBASE) moves
    PMAX and Uo to the start plus 0.1 p.u., noted; IBLOCK 3 sets zero limits to the start."""
    p = params(Wsieg1, records["gridpack39"]["WSIEG1"][:2], iblock=np.array([0.0, 3.0]),
               pmin=np.array([0.0, 0.0]), pmax=np.array([1.01, 0.0]))
    p, x, *_ = Wsieg1.init(p, start(jnp.array([1.121, 0.6])))
    assert float(p["pmax"][0]) == pytest.approx(1.121 + WIDEN_MARGIN)
    assert float(p["uo"][0]) == pytest.approx(1.121 + WIDEN_MARGIN)
    assert (float(p["pmin"][1]), float(p["pmax"][1])) == pytest.approx((0.6, 0.6))
    assert not any(np.any(v) for v in Wsieg1.init_violations(p, x).values())
    notes = Wsieg1.notes(p, ("unit 31", "unit 32"))
    assert any(n.startswith("unit 31: initial valve 1.121 is outside PMAX = 1.01: PMAX set to "
                            "1.221") for n in notes), notes


def test_wsieg1_unmodelled_deadband_is_rejected(tmp_path):
    record = next(line for line in GRIDPACK_DYR.read_text(encoding="utf-8-sig").splitlines()
                  if "'WSIEG1'" in line)
    values = record.split(",")
    values[25] = " 0.0005"  # DB1, the 21st CON after two ICONs
    message = read_error(Wsieg1, tmp_path, ",".join(values) + "\n")
    assert re.search(r":1: WSIEG1 at bus 30 .*DB1 != 0: WSIEG1 deadbands and valve-gain table "
                     r"are not modelled", message), message


# --------------------------------------------------------------------------- #
# GGOV1 (its CON order and description: jaxgrid.models.governors.Ggov1)
# --------------------------------------------------------------------------- #

# Rselect Flag R Tpelec maxerr minerr Kpgov Kigov Kdgov Tdgov Vmax Vmin Tact Kturb Wfnl Tb Tc
# Teng Tfload Kpload Kiload Ldref Dm Ropen Rclose Kimw Aset Ka Ta Trate db Tsa Tsb Rup Rdown
GGOV1 = (1, 1, 0.04, 1, 0.05, -0.05, 10, 2, 0, 1, 1, 0.15, 0.5, 1.5, 0.2, 0.1, 0, 0, 3, 2, 0.67,
         1, 0, 0.1, -0.1, 0, 0.01, 10, 0.1, 0, 0, 4, 5, 99, -99)


def ggov1(values=GGOV1, line: int = 1, source: str = "hand.dyr") -> list:
    return [DyrRecord(model="GGOV1", bus=1, device_id="1", cons=tuple(map(float, values)),
                      icons=(), header=(), record_type="GGOV1", line=line, source=source)]


def ggov1_start(p, pm0, pe0, mbase=100.0):
    pm0 = jnp.asarray(pm0, dtype=float)
    return Ggov1.init(p, GovernorStart(pm0, jnp.asarray(pe0, dtype=float),
                                       jnp.full_like(pm0, mbase)))


def test_ggov1_texas_records_start_at_rest(records):
    recs = records["activsg"]["GGOV1"]
    assert len(recs) == 367
    p = params(Ggov1, recs)
    pm0 = jnp.linspace(0.3, 0.8, len(recs))  # MW / Trate inside (Vmin, Vmax) for all
    p, x, *_ = ggov1_start(p, pm0, pm0 - 0.002, mbase=np.asarray(p["trate"]))
    assert not any(np.any(v) for v in Ggov1.init_violations(p, x).values())
    pm, dx = Ggov1.rates(p, x, GovernorPorts(jnp.zeros(len(recs)), pm0 - 0.002))
    for state, d in dx.items():
        assert float(jnp.max(jnp.abs(d))) < STEADY_TOL, f"GGOV1 d{state}/dt = {d}"
    assert float(jnp.max(jnp.abs(pm - pm0))) < STEADY_TOL


def test_ggov1_droop_settles_with_pelec_feedback():
    """Rselect 1 and Pe following Pm (a machine at constant speed): a speed 0.2 % low
    settles where the error vanishes, Pref − Δω − R·Pe = 0, Pe = Pe0 + 0.002/R = Pe0 + 0.05,
    through the PI, the rate-limited actuator and the turbine lag (explicit Euler, 10 ms)."""
    p = params(Ggov1, ggov1())
    p, x, *_ = ggov1_start(p, [0.55], [0.55])
    dt, dw = 0.01, jnp.array([-0.002])

    @jax.jit
    def run(x):
        def step(_, carry):
            x, pe = carry
            pm, dx = Ggov1.rates(p, x, GovernorPorts(dw, pe))
            x = {k: v + dt * dx[k] for k, v in x.items()}
            return {k: jnp.clip(v, *Ggov1.limits(p)[k]) if k in Ggov1.limits(p) else v
                    for k, v in x.items()}, pm
        return jax.lax.fori_loop(0, 20_000, step, (x, jnp.array([0.55])))

    _, pm = run(x)
    assert float(pm[0]) == pytest.approx(0.55 + 0.002 / 0.04, abs=SETTLED_TOL)


def test_ggov1_acceleration_limiter_ramps_fsr_down():
    """The speed error switched off (maxerr = minerr = 0) and Pe held: a speed rising at
    a = 0.02 p.u./s, above Aset = 0.01, makes fsra = m + Ka·DELT·(Aset − a) the lowest
    request once the Ta lag has caught the acceleration (to e^(−10) by 1 s), and fsr (its
    memory m) falls at Ka·(a − Aset) = 0.1 p.u./s, from 0.567 toward Vmin = 0.15 (reached
    after 4 s); at rest (a = 0) fsra lies Ka·DELT·Aset above fsr."""
    values = list(GGOV1)
    values[4:6] = [0.0, 0.0]
    p = params(Ggov1, ggov1(values))
    p, x, *_ = ggov1_start(p, [0.55], [0.55])
    dt, a = 1e-3, 0.02

    @jax.jit
    def run(x):
        def step(n, x):
            dx = Ggov1.rates(p, x, GovernorPorts(jnp.array([a * n * dt]), jnp.array([0.55])))[1]
            return {k: v + dt * dx[k] for k, v in x.items()}
        x1 = jax.lax.fori_loop(0, 1000, step, x)
        return x1, jax.lax.fori_loop(1000, 1500, step, x1)

    x1, x2 = run(x)
    slope = float(x2["x_fsr"][0] - x1["x_fsr"][0]) / 0.5
    assert slope == pytest.approx(-10 * (a - 0.01), rel=1e-4)


def test_ggov1_initial_stroke_outside_limits_moves_kturb_and_vmin():
    """GridPACK's rules, Kturb 1: Pmech0 = 0.9 needs a stroke 0.9 + 0.2 = 1.1 > Vmax = 1:
    Kturb becomes 0.9/(1 − 0.2) = 1.125; Pmech0 = 0 needs 0.2 < Vmin 0.3: Vmin becomes 0.2.
    Both then start at rest (Pmech0 < Ldref: the load limit is not reached)."""
    values = list(GGOV1)
    values[11], values[13] = 0.3, 1.0  # Vmin, Kturb
    p = params(Ggov1, ggov1(values) * 2)
    p, x, *_ = ggov1_start(p, [0.9, 0.0], [0.9, 0.0])
    assert np.asarray(p["kturb"]) == pytest.approx([1.125, 1.0])
    assert np.asarray(p["vmin"]) == pytest.approx([0.3, 0.2])
    assert not any(np.any(v) for v in Ggov1.init_violations(p, x).values())
    _, dx = Ggov1.rates(p, x, GovernorPorts(jnp.zeros(2), jnp.array([0.9, 0.0])))
    assert max(float(jnp.max(jnp.abs(d))) for d in dx.values()) < STEADY_TOL
    notes = Ggov1.notes({k: np.asarray(v) for k, v in p.items()}, ("u1", "u2"))
    assert notes == ["u1: loaded beyond Kturb·(Vmax − Wfnl) at the power flow: its initial "
                     "stroke put at Vmax: KTURB = 1 set to 1.125 (GridPACK's rule)",
                     "u2: the initial stroke lies below VMIN: VMIN = 0.3 set to 0.2 "
                     "(GridPACK's rule)"], notes


@pytest.mark.parametrize("changes, pattern", [
    ({0: -1}, r"ICON Rselect = -1: supported 1 .* -1 and -2 are not modelled"),
    ({1: 2}, r"ICON Flag = 2: allowed 0 .*, 1"),
    ({17: 0.5}, r"TENG = 0.5 s: the transport delay is not modelled"),
    ({6: 0}, r"CON\(5\) KPGOV = 0 p.u.: must be > 0"),
    ({28: 0}, r"TA = 0 with KA = 10: needs TA > 0 or KA = 0"),
    ({16: 0.2, 15: 0}, r"TB = 0 with TC = 0.2"),
])
def test_ggov1_bad_data_names_the_record(changes, pattern):
    values = list(GGOV1)
    for k, v in changes.items():
        values[k] = v
    with pytest.raises(ModelError, match=rf"^bad\.dyr:3: GGOV1 at bus 1 id '1': {pattern}"):
        Ggov1.read(ggov1(values, line=3, source="bad.dyr"))
