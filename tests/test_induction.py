"""Induction-motor loads CIM5BL and CIM6BL (`jaxgrid.models.induction`, spec induction-motors.md).

1. The §4 equations at steady state reproduce the exact double-cage circuit Z(s) (§3.1).
2. Initialisation: at rest, drawing exactly the record's P, on the stable side of breakdown.
3. Bad data raise a ModelError naming file:line (CONs, ICON, and "cannot carry its load").
4. Under-voltage trip timing and latching (§7); a tripped motor draws nothing and is frozen.
5. Against ANDES (CURENT, PyPI `andes`): single cage vs Motor3, double cage vs Motor5, on a
   stiff bus whose voltage dips 1.0 -> 0.7 -> 1.0 p.u. Our side integrates `rates` with
   RK4 on ANDES's own time grid under ANDES's bus voltage. The differences are ANDES's
   trapezoid error (they fall 4x when its step halves).
6. An independent check: the speed after a voltage step settles at the torque balance of the
   exact circuit. 7. jit, vmap and float32.
"""
from __future__ import annotations

import logging
import re
import time
from pathlib import Path
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrid.io.dyr import read_dyr
from jaxgrid.models.base import LoadPorts, LoadSite, ModelError, device_label
from jaxgrid.models.induction import (INDUCTION_MOTORS, Cim5bl, Cim6bl, circuit_impedance,
                                      motor_constants, steady_impedance)

F_NOM = 60.0
OMEGA_B = 2 * np.pi * F_NOM
SBASE = 100.0
V0 = 1.02 * np.exp(0.3j)    # bus voltage at the power flow, p.u.
RECORD_P = 0.3              # load record P at V0, p.u. system base (30 MW)
KEEP_ALL = SimpleNamespace(stiff_below=0.0)    # model every second cage
DEFAULT = SimpleNamespace(stiff_below=0.01)    # 2 × a 5 ms step

STEADY_TOL = 1e-9       # float64 |derivative| at an exact steady state (rates up to ~1e2/s)
IMPEDANCE_TOL = 1e-10   # relative, §4 steady state vs the exact circuit
POWER_TOL = 1e-12       # p.u., s0 against the record's P and against current(V0)
FLOAT32_TOL = 1e-4      # float32 |derivative| at rest: 6e-8 round-off × rates up to ~1e2/s
                        # (measured <= 1.5e-5)

# CON lists after IT (PSS/E order); see the Con tables in jaxgrid/models/induction.py.
#            RA    XA   XM   R1    X1    R2    X2   E1  SE1  E2  SE2  MBASE PMULT H   VI  TI TB
SINGLE = "1  0.01 0.1  3.0  0.02  0.12  0     0    0   0    0   0    0     1.3   0.6 0.7 6  3"
DOUBLE = "1  0.01 0.1  3.0  0.01  0.12  0.05  0.1  0   0    0   0    0     1.3   0.6 0.7 6  3"
SATUR = "1  0.01 0.1  3.0  0.02  0.12  0     0    1.0 0.05 1.2 0.2  50    0     0.6 0   0  0"
TYPE2 = "2  0.01 0.1  3.0  0.1   0.08  0.008 0.1  0   0    0   0    0     1.3   0.6 0.7 6  3"
CIM5_TAIL = "2.0 0"             # D (exponent), TNOM
CIM6_TAIL = "0.3 0.2 0.1 1.5 0 0"  # A B D E C0 TNOM


@pytest.fixture(autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


def records(tmp_path: Path, lines: list[str], name: str = "m.dyr"):
    """DYR records of `lines` ("MODEL cons"), one per bus 1, 2, ..., written to a file."""
    text = "\n".join(f"{k + 1} '{line.split()[0]}' 1 {line.split(None, 1)[1]} /"
                     for k, line in enumerate(lines))
    path = tmp_path / name
    path.write_text("// induction-motor test data\n" + text + "\n")
    return read_dyr(path).records


def site(recs, v0=V0, record_p=RECORD_P) -> LoadSite:
    n = len(recs)
    return LoadSite(v0=np.full(n, v0, dtype=complex), record_s=np.full(n, record_p),
                    bus_p=np.full(n, record_p), sbase=SBASE, f_nom=F_NOM,
                    labels=tuple(device_label(r) for r in recs), motors=DEFAULT)


def initialised(model, recs, options=DEFAULT, **site_args):
    """(p, x, z, s0, notes, site) with p, x, z as jnp arrays."""
    where = site(recs, **site_args)._replace(motors=options)
    p, x, out, z, notes = model.init(model.read(recs), where)
    s0 = out["s0"]
    to_jnp = lambda d: {k: jnp.asarray(v) for k, v in d.items()}  # noqa: E731
    return to_jnp(p), to_jnp(x), to_jnp(z), s0, notes, where


def max_rate(dx) -> float:
    return max(float(jnp.max(jnp.abs(v))) for v in dx.values())


# --------------------------------------------------------------------------- #
# 1. Steady state of §4 = exact circuit
# --------------------------------------------------------------------------- #

SLIPS = (1e-4, 0.003, 0.02, 0.1, 0.4, 1.0)


@pytest.mark.parametrize("cons", [SINGLE, DOUBLE], ids=["single", "double"])
def test_closed_form_steady_state_is_the_circuit(tmp_path, cons):
    p = Cim5bl.read(records(tmp_path, [f"CIM5BL {cons} {CIM5_TAIL}"]))
    c = dict(p, **motor_constants(p, np.full(1, OMEGA_B), 0.0), omega_b=np.full(1, OMEGA_B))
    for s in SLIPS:
        z4 = steady_impedance(c, s)[2]
        zc = circuit_impedance(p, s)
        assert np.abs(z4 - zc) / np.abs(zc) < IMPEDANCE_TOL, f"s = {s}: {z4} vs {zc}"


@pytest.mark.parametrize("cons", [SINGLE, DOUBLE], ids=["single", "double"])
def test_derivative_at_rest_reproduces_circuit_impedance(tmp_path, cons):
    """At fixed speed, the states where `rates` vanishes give V/I = Z(s) of the circuit."""
    recs = records(tmp_path, [f"CIM5BL {cons} {CIM5_TAIL}"])
    p, x, z, *_ = initialised(Cim5bl, recs, KEEP_ALL)
    v = jnp.asarray([1.0 + 0j])
    names = ("epr", "epi", "psir", "psii")

    @jax.jit
    def rates(y, w):
        dx = Cim5bl.rates(p, dict(zip(names, y[:, None]), w=w), LoadPorts(v, z))[1]
        return jnp.stack([dx[k][0] for k in names])

    for s in SLIPS:
        w = jnp.asarray([1.0 - s])
        y0 = jnp.zeros(4)
        jac = jax.jit(jax.jacfwd(rates))(y0, w)  # affine in the EMFs (no saturation)
        keep = np.flatnonzero(np.abs(np.asarray(jac)).sum(axis=1) > 0)  # ψk held: single
        y = np.zeros(4)
        y[keep] = np.linalg.solve(np.asarray(jac)[np.ix_(keep, keep)],
                                  -np.asarray(rates(y0, w))[keep])
        xs = dict(zip(names, jnp.asarray(y)[:, None]), w=w)
        _, dx = Cim5bl.rates(p, xs, LoadPorts(v, z))
        assert max_rate({k: dx[k] for k in names}) < STEADY_TOL  # ω held: its rate is not 0
        i_motor = Cim5bl.current(p, xs, z, v) / p["sm"]
        z_model = complex(v[0] / i_motor[0])
        zc = complex(circuit_impedance(Cim5bl.read(recs), s)[0])
        assert abs(z_model - zc) / abs(zc) < IMPEDANCE_TOL, f"s = {s}: {z_model} vs {zc}"


# --------------------------------------------------------------------------- #
# 2. Initialisation
# --------------------------------------------------------------------------- #

CASES = {
    "cim5_single": ("CIM5BL", SINGLE, CIM5_TAIL, KEEP_ALL),
    "cim5_double": ("CIM5BL", DOUBLE, CIM5_TAIL, KEEP_ALL),
    "cim5_double_dropped": ("CIM5BL", DOUBLE, CIM5_TAIL, SimpleNamespace(stiff_below=0.05)),
    "cim5_saturated": ("CIM5BL", SATUR, CIM5_TAIL, DEFAULT),
    "cim6_double": ("CIM6BL", DOUBLE, CIM6_TAIL, DEFAULT),
    "cim6_type2": ("CIM6BL", TYPE2, CIM6_TAIL, KEEP_ALL),
    "cim6_type2_dropped": ("CIM6BL", TYPE2, CIM6_TAIL, DEFAULT),
}


@pytest.mark.parametrize("case", list(CASES))
def test_init_is_at_rest_and_draws_the_record(tmp_path, case):
    name, cons, tail, options = CASES[case]
    model = INDUCTION_MOTORS[name]
    recs = records(tmp_path, [f"{name} {cons} {tail}"])
    p, x, z, s0, notes, where = initialised(model, recs, options)
    v = jnp.asarray(where.v0)
    assert max_rate(model.rates(p, x, LoadPorts(v, z))[1]) < STEADY_TOL, case
    drawn = np.asarray(v * jnp.conj(model.current(p, x, z, v)))
    np.testing.assert_allclose(drawn, s0, atol=POWER_TOL, err_msg=case)
    np.testing.assert_allclose(s0.real, where.record_p, atol=POWER_TOL, err_msg=case)
    assert np.all(s0.imag > 0), f"{case}: an induction motor draws vars ({s0.imag})"
    # Norton form: current = y_norton·(V − E'')
    epp = p["k5"] * (x["epr"] + 1j * x["epi"]) + p["k4"] * (x["psir"] + 1j * x["psii"])
    np.testing.assert_allclose(np.asarray(p["y_norton"] * (v - epp)),
                               np.asarray(model.current(p, x, z, v)), atol=1e-14)
    assert re.search(r"m\.dyr:2: .* slip s0 = ", notes[0]), notes
    assert ("second cage dropped" in " ".join(notes)) == case.endswith("dropped"), notes


def test_init_slip_is_the_low_root_of_the_circuit(tmp_path):
    """s0 solves P_circuit(s) = P/Sm and lies below breakdown (torque still rising)."""
    recs = records(tmp_path, [f"CIM5BL {DOUBLE} {CIM5_TAIL}"])
    p, x, _, s0, notes, where = initialised(Cim5bl, recs, KEEP_ALL)
    cons = Cim5bl.read(recs)
    slip = 1.0 - float(x["w"][0])
    vmag2 = abs(V0) ** 2
    power = lambda s: vmag2 * np.real(1 / circuit_impedance(cons, s))[0]  # noqa: E731
    torque = lambda s: vmag2 * np.real((circuit_impedance(cons, s) - cons["ra"])  # noqa: E731
                                       / np.abs(circuit_impedance(cons, s)) ** 2)[0]
    assert power(slip) * float(p["sm"][0]) == pytest.approx(RECORD_P, abs=POWER_TOL)
    assert torque(slip * 1.01) > torque(slip), "initial slip beyond breakdown"
    assert "Sm = 39.000 MVA (MBASE = 0: Sm = PMULT × P = 1.3 × 30.000 MW)" in notes[0], notes


def test_cim6_c0_and_torque_balance(tmp_path):
    recs = records(tmp_path, [f"CIM6BL {DOUBLE} {CIM6_TAIL}"])
    p, x, _, _, notes, where = initialised(Cim6bl, recs)
    w0 = x["w"]
    bracket = p["a"] * w0 ** 2 + p["b"] * w0 + p["c0"] + p["d"] * w0 ** p["e"]
    np.testing.assert_allclose(np.asarray(bracket), 1.0, atol=1e-14)
    te0 = Cim6bl.electrical_torque(p, x, jnp.asarray(where.v0))
    np.testing.assert_allclose(np.asarray(Cim6bl.load_torque(p, w0)), np.asarray(te0), atol=1e-14)
    assert any("C0 = 0 in the file" in line for line in notes), notes


# --------------------------------------------------------------------------- #
# 3. Bad data
# --------------------------------------------------------------------------- #

def _with(cons: str, **changes) -> str:
    """SINGLE-style CON string with fields replaced by name."""
    names = ["it", "ra", "xa", "xm", "r1", "x1", "r2", "x2", "e1", "se1", "e2", "se2",
             "mbase", "pmult", "h", "vi", "ti", "tb"]
    values = cons.split()
    for key, value in changes.items():
        values[names.index(key)] = str(value)
    return " ".join(values)


@pytest.mark.parametrize("cons, message", [
    (_with(SINGLE, xm=0), r"CON\(3\) XM = 0 p\.u\.: must be > 0"),
    (_with(SINGLE, r1=0), r"CON\(4\) R1 = 0 p\.u\.: must be > 0"),
    (_with(SINGLE, h=0), r"CON\(14\) H = 0 s: must be > 0"),
    (_with(SINGLE, ti=-1), r"CON\(16\) TI = -1 cycles: must lie in"),
    (_with(SINGLE, mbase=0, pmult=0), r"MBASE = PMULT = 0"),
    (_with(SINGLE, it=3), r"ICON IT = 3: allowed 1 .* or 2"),
    (_with(TYPE2, r2=0), r"IT = 2 \(deep-bar ladder\) needs both cages"),
    (_with(DOUBLE, x1=0), r"X1 = 0 with a second cage"),
    (_with(SATUR, se2=0.01), r"saturation needs S2·E2 > S1·E1"),
    (SINGLE.rsplit(None, 1)[0], r"expected 20 values, found 19"),
])
def test_bad_cons_name_file_and_line(tmp_path, cons, message):
    recs = records(tmp_path, [f"CIM5BL {SINGLE} {CIM5_TAIL}", f"CIM5BL {cons} {CIM5_TAIL}"])
    with pytest.raises(ModelError, match=r"m\.dyr:3: CIM5BL at bus 2 id '1': " + message):
        Cim5bl.read(recs)


@pytest.mark.parametrize("record_p, v0, message", [
    (1.0, V0, "motor cannot carry its load at V0 = 1.0200 p.u.: P/Sm exceeds the power at "
              "breakdown torque"),
    (0.3, 0.3 + 0j, "motor cannot carry its load at V0 = 0.3000"),
    (0.0, V0, "the load record draws P = 0 MW"),
])
def test_motor_that_cannot_carry_its_load(tmp_path, record_p, v0, message):
    pmult = "0.3" if record_p == 1.0 else "1.3"  # Sm = 30 MVA for a 100 MW load: p = 3.3
    recs = records(tmp_path, [f"CIM5BL {_with(DOUBLE, pmult=pmult)} {CIM5_TAIL}"])
    with pytest.raises(ModelError, match=re.escape(f"m.dyr:2: CIM5BL at bus 1 id '1': {message}")):
        Cim5bl.init(Cim5bl.read(recs), site(recs, v0=v0, record_p=record_p))


def test_partial_saturation_data_is_reported(tmp_path):
    recs = records(tmp_path, [f"CIM5BL {_with(SATUR, se1=0)} {CIM5_TAIL}"])
    p, *_, notes, _ = initialised(Cim5bl, recs)
    assert float(p["sat_b"][0]) == 0.0
    assert any("incomplete: no saturation" in line for line in notes), notes


# --------------------------------------------------------------------------- #
# 4. Under-voltage trip
# --------------------------------------------------------------------------- #

@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_uv_trip_timing_and_latch(tmp_path, dtype):
    """TI = 6, TB = 3 cycles at 60 Hz: status 0 after exactly 0.15 s below VI, latched."""
    recs = records(tmp_path, [f"CIM5BL {SINGLE} {CIM5_TAIL}"] * 3)
    p, x, z, *_ = initialised(Cim5bl, recs)
    p = {k: v.astype(dtype) if v.dtype == jnp.float64 else v for k, v in p.items()}
    z = {k: v.astype(dtype) for k, v in z.items()}
    p["vi"] = p["vi"].at[2].set(0.0)  # unit 2: no relay
    dt = 1.0 / 600.0                  # a cycle is 10 steps
    step = jax.jit(lambda z, v: Cim5bl.update(p, x, z, v, v, dt))
    low = jnp.asarray([0.5, 0.5, 0.5], dtype=jnp.complex64 if dtype == jnp.float32 else complex)
    # unit 1: the voltage recovers after 7 cycles (picked up at 6): it must trip anyway
    status = []
    for k in range(1, 121):
        v = low.at[1].set(1.0) if k > 70 else low
        z = step(z, v)
        status.append(np.asarray(z["status"]))
    status = np.array(status)
    t_trip = (6 + 3) / F_NOM          # (TI + TB)/f_nom = 0.15 s
    n_trip = round(t_trip / dt)       # status 0 after this many steps
    assert np.all(status[:n_trip - 1, :2] == 1) and np.all(status[n_trip - 1:, :2] == 0), \
        f"trip steps {np.argmax(status[:, :2] == 0, axis=0) + 1}, expected {n_trip}"
    assert np.all(status[:, 2] == 1), "VI = 0 must never trip"
    assert z["picked"].dtype == dtype


def test_short_dip_does_not_pick_up(tmp_path):
    recs = records(tmp_path, [f"CIM5BL {SINGLE} {CIM5_TAIL}"])
    p, x, z, *_ = initialised(Cim5bl, recs)
    dt = 1.0 / 600.0
    for k in range(200):  # 5 cycles low, 5 cycles high, repeated: never TI = 6 cycles in a row
        v = jnp.asarray([0.5 + 0j if (k // 50) % 2 == 0 else 1.0 + 0j])
        z = Cim5bl.update(p, x, z, v, v, dt)
    assert float(z["picked"][0]) == 0.0 and float(z["status"][0]) == 1.0


def test_tripped_motor_draws_nothing_and_is_frozen(tmp_path):
    recs = records(tmp_path, [f"CIM5BL {DOUBLE} {CIM5_TAIL}"])
    p, x, z, *_ = initialised(Cim5bl, recs)
    z = dict(z, status=jnp.zeros(1))
    v = jnp.asarray([0.4 + 0.1j])
    assert float(jnp.abs(Cim5bl.current(p, x, z, v))[0]) == 0.0
    assert max_rate(Cim5bl.rates(p, x, LoadPorts(v, z))[1]) == 0.0


# --------------------------------------------------------------------------- #
# 5. Against ANDES Motor3 / Motor5
# --------------------------------------------------------------------------- #

ANDES_DIPS = ((0.2, 0.7), (0.4, 1.0))   # (time s, slack voltage p.u.)
ANDES_T_END = 1.0
ANDES_EVENT_EPS = 1e-7  # s; ANDES's sub-step around events (default 1e-4, see below)
SM_MVA = 50.0
# Our RK4 error is negligible at these steps; ANDES's implicit trapezoid error is O(h²):
# at h = 1 ms the differences below were measured at about a quarter of these bounds,
# and they fall by 4x when h halves (checked as the order of convergence).
ANDES_TOL = {"slip": 3e-6, "p": 1e-4, "q": 4e-4}  # p.u. system base, h = 1 ms
CIRCUIT = dict(ra=0.01, xa=0.1, xm=3.0, x1=0.12)


def andes_double_cage(ra, xa, xm, r1, x1, r2, x2):
    """ANDES Motor5 data whose operational reactance equals the exact double-cage circuit.

    Motor5 uses the partial-fraction form X(p) = x'' + (x' − x'')/(1 + pT''0) +
    (x0 − x')/(1 + pT'0) with T'0, T''0 computed from its circuit data by the classical
    approximations. Here the exact open-circuit poles and residues of the circuit are
    computed, and Motor5 data are chosen so that its constants equal them; both models then
    have the same rotor transfer function, hence the same response at any speed.
    """
    p1, p2 = np.poly1d([x1, OMEGA_B * r1]), np.poly1d([x2, OMEGA_B * r2])
    num = p1 * p2
    den = num + np.poly1d([xm, 0.0]) * (p1 + p2)
    fast, slow = np.sort(np.real(den.r))
    tp0, tpp0 = -1.0 / slow, -1.0 / fast
    ls, lpp = xa + xm, xa + 1.0 / (1.0 / xm + 1.0 / x1 + 1.0 / x2)
    lp = ls - tp0 * xm * num(slow) / den.deriv()(slow)
    l1, l2 = lp - xa, lpp - xa
    xr1 = l1 * xm / (xm - l1)
    xr2 = 1.0 / (1.0 / l2 - 1.0 / xr1 - 1.0 / xm)
    data = dict(rs=ra, xs=xa, xm=xm, xr1=xr1, xr2=xr2, rr1=(xr1 + xm) / (OMEGA_B * tp0),
                rr2=(xr2 + l1) / (OMEGA_B * tpp0))
    z_andes = lambda s: ra + 1j * (lpp + (lp - lpp) / (1 + 1j * OMEGA_B * s * tpp0)  # noqa
                                   + (ls - lp) / (1 + 1j * OMEGA_B * s * tp0))
    return data, z_andes


def run_andes_motor(model: str, data: dict, tstep: float, slip_guess: float = 0.02):
    """ANDES on one slack bus (stiff, voltage stepped by `Alter`) feeding one motor.

    Returns (t, v, slip, p, q (n_t,), power-flow {p, q, te, slip}, TDS wall s). Three
    adjustments, none to the equations: the slip's initial guess (ANDES starts its power
    flow from slip = 1 and would converge to the high-slip root), SciPy's sparse solver
    (KLU crashes on this one-bus system), and the sub-step ANDES takes around each event
    (`store_switch_times` eps): ANDES's trapezoid reuses the pre-event derivative in the
    first step after a switch, an error of eps/2 × the jump of the rates; with the default
    1e-4 s it alone gives ~1e-3 p.u. in Q, at 1e-7 s it vanishes.
    """
    import andes
    from andes.linsolvers.solverbase import Solver

    andes.config_logger(stream_level=logging.ERROR)
    ss = andes.System(default_config=True, no_output=True)
    ss.add("Bus", {"idx": 1, "name": "B1", "Vn": 110.0, "v0": 1.0, "a0": 0.0})
    ss.add("Slack", {"idx": 1, "bus": 1, "Sn": SBASE, "Vn": 110.0, "v0": 1.0, "a0": 0.0,
                     "p0": 0.0, "q0": 0.0, "qmax": 99.0, "qmin": -99.0, "pmax": 99.0,
                     "pmin": -99.0})
    ss.add(model, dict(idx=1, bus=1, Vn=110.0, fn=F_NOM, Sn=SM_MVA, **data))
    for k, (t, v) in enumerate(ANDES_DIPS):
        ss.add("Alter", {"idx": k + 1, "t": t, "model": "Slack", "dev": 1, "src": "v0",
                         "attr": "v", "method": "=", "amount": v})
    ss.setup()
    ss.PFlow.solver = Solver("spsolve")
    ss.TDS.solver = Solver("spsolve")
    motor = getattr(ss, model)
    pf_init, store = ss.PFlow.init, ss.store_switch_times

    def init_with_guess():
        out = pf_init()
        ss.dae.x[motor.slip.a] = slip_guess
        return out

    ss.PFlow.init = init_with_guess
    ss.store_switch_times = lambda models, eps=ANDES_EVENT_EPS: store(models, eps=eps)
    ss.PFlow.config.report = 0
    assert ss.PFlow.run(), "ANDES power flow failed"
    pf = {k: float(getattr(motor, k).v[0]) for k in ("p", "q", "te", "slip")}
    ss.TDS.config.tf, ss.TDS.config.tstep = ANDES_T_END, tstep
    ss.TDS.config.fixt, ss.TDS.config.no_tqdm = 1, 1
    start = time.perf_counter()
    ss.TDS.run()
    wall = time.perf_counter() - start
    ts = ss.dae.ts
    vm, va = ts.y[:, ss.Bus.v.a][:, 0], ts.y[:, ss.Bus.a.a][:, 0]
    return (np.asarray(ts.t), vm * np.exp(1j * va), ts.x[:, motor.slip.a][:, 0],
            ts.y[:, motor.p.a][:, 0], ts.y[:, motor.q.a][:, 0], pf, wall)


def follow(model, p, x, z, t, v):
    """RK4 from x over the time grid t (n_t,) with bus voltage v[k+1] on (t_k, t_k+1].

    Returns (slip, complex power drawn) (n_t,), p.u. system base.
    """
    def rk4(x, step):
        h, vk = step
        f = lambda y: model.rates(p, y, LoadPorts(vk, z))[1]  # noqa: E731
        k1 = f(x)
        k2 = f({k: x[k] + 0.5 * h * k1[k] for k in x})
        k3 = f({k: x[k] + 0.5 * h * k2[k] for k in x})
        k4 = f({k: x[k] + h * k3[k] for k in x})
        x = {k: x[k] + h / 6 * (k1[k] + 2 * k2[k] + 2 * k3[k] + k4[k]) for k in x}
        return x, x

    vs = jnp.asarray(v)[:, None]
    _, xs = jax.jit(lambda x: jax.lax.scan(rk4, x, (jnp.diff(jnp.asarray(t)), vs[1:])))(x)
    xs = {k: jnp.concatenate([x[k][None], xs[k]]) for k in xs}
    current = jax.vmap(lambda y, vk: model.current(p, y, z, vk))(xs, vs)
    return 1.0 - np.asarray(xs["w"])[:, 0], np.asarray(vs * jnp.conj(current))[:, 0]


def _ours_against(model, cons: dict, ref):
    """Errors of our motor, initialised on ANDES's power flow, along ANDES's run `ref`."""
    t, v, slip, p_ref, q_ref, pf, _ = ref
    p = {k: np.array([float(val)]) for k, val in cons.items()}
    p["it"] = np.array([1.0])
    where = LoadSite(v0=v[:1], record_s=np.array([pf["p"]]), bus_p=np.array([pf["p"]]),
                     sbase=SBASE, f_nom=F_NOM, motors=KEEP_ALL)
    p, x, out, z, _ = model.init(p, where)
    s0 = out["s0"]
    to_jnp = lambda d: {k: jnp.asarray(val) for k, val in d.items()}  # noqa: E731
    our_slip, s = follow(model, to_jnp(p), to_jnp(x), to_jnp(z), t, v)
    return ({"slip": np.abs(our_slip - slip).max(), "p": np.abs(s.real - p_ref).max(),
             "q": np.abs(s.imag - q_ref).max()},
            {"slip": abs(our_slip[0] - pf["slip"]), "q": abs(s0.imag[0] - pf["q"])})


def _motor_cases():
    single = dict(CIRCUIT, r1=0.02, r2=0.0, x2=0.0)
    double = dict(CIRCUIT, r1=0.01, r2=0.05, x2=0.1)
    data2, _ = andes_double_cage(**double)
    common = dict(e1=0, se1=0, e2=0, se2=0, mbase=SM_MVA, pmult=0, h=0.6, vi=0, ti=0, tb=0)
    # Motor3: tm = c2 ω² + (2c3 − c2) ω + (c1 + c2 − c3) = 0.4 ω²: CIM5BL with D = 2
    motor3 = ("Motor3", dict(rs=0.01, xs=0.1, xm=3.0, rr1=0.02, xr1=0.12, Hm=0.6,
                             c1=-0.2, c2=0.4, c3=0.2),
              Cim5bl, lambda te0: dict(single, **common, d=2.0, tnom=0.0))
    # Motor5: tm = 0.2 ω² + 0.1 ω + 0.15 (system base): CIM6BL with A, B scaled by Te0
    c1, c2, c3 = 0.1, 0.2, 0.15
    motor5 = ("Motor5", dict(data2, Hm=0.6, c1=c1, c2=c2, c3=c3), Cim6bl,
              lambda te0: dict(double, **common, a=c2 / te0, b=(2 * c3 - c2) / te0, d=0.0,
                               e=1.0, c0=0.0, tnom=0.0))
    return {"motor3_single_cage": motor3, "motor5_double_cage": motor5}


def test_andes_double_cage_mapping_is_exact():
    double = dict(CIRCUIT, r1=0.01, r2=0.05, x2=0.1)
    _, z_andes = andes_double_cage(**double)
    cons = {k: np.array([v]) for k, v in double.items()}
    for s in SLIPS:
        zc = circuit_impedance(cons, s)[0]
        assert abs(z_andes(s) - zc) / abs(zc) < IMPEDANCE_TOL, s


@pytest.mark.parametrize("case", ["motor3_single_cage", "motor5_double_cage"])
def test_against_andes(case):
    andes_model, data, model, cons_for = _motor_cases()[case]
    errors = {}
    for tstep in (0.002, 0.001):
        ref = run_andes_motor(andes_model, data, tstep)
        errors[tstep], at_init = _ours_against(model, cons_for(ref[5]["te"]), ref)
    assert at_init["slip"] < 1e-8 and at_init["q"] < 1e-7, f"{case}: initial point {at_init}"
    print(f"\n{case}: max errors vs ANDES, h = 2 ms {errors[0.002]}, h = 1 ms {errors[0.001]}")
    for key, tol in ANDES_TOL.items():
        assert errors[0.001][key] < tol, f"{case}: {key} error {errors[0.001][key]:.3g} > {tol}"
        ratio = errors[0.002][key] / errors[0.001][key]
        assert ratio > 3.0, f"{case}: {key} error falls only {ratio:.2f}x when h halves"


# --------------------------------------------------------------------------- #
# 6. Settling at the circuit's torque balance after a voltage step
# --------------------------------------------------------------------------- #

@pytest.mark.parametrize("name, tail", [("CIM5BL", CIM5_TAIL), ("CIM6BL", CIM6_TAIL)])
def test_settles_at_circuit_torque_balance(tmp_path, name, tail):
    model = INDUCTION_MOTORS[name]
    recs = records(tmp_path, [f"{name} {DOUBLE} {tail}"])
    p, x, z, *_ = initialised(model, recs, KEEP_ALL)
    v_new = 0.9 * V0
    t = np.arange(0.0, 4.0 + 1e-9, 1e-3)
    slip, _ = follow(model, p, x, z, t, np.full(t.shape, v_new))
    cons = model.read(recs)

    def gap(s):  # air-gap torque of the exact circuit minus the load torque, p.u. Sm
        zc = circuit_impedance(cons, s)[0]
        te = abs(v_new) ** 2 * np.real(zc - cons["ra"][0]) / abs(zc) ** 2
        return te - float(model.load_torque(p, jnp.asarray([1.0 - s]))[0])

    lo, hi = 1e-6, 0.5 * (1.0 - float(x["w"][0])) + 0.1
    assert gap(lo) < 0 < gap(hi)
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if gap(mid) < 0 else (lo, mid)
    assert slip[-1] == pytest.approx(0.5 * (lo + hi), abs=1e-9), f"{name}: {slip[-1]} vs {lo}"
    assert slip[-1] > 1.0 - float(x["w"][0]), "a lower voltage must raise the slip"


# --------------------------------------------------------------------------- #
# 7. jit, vmap, float32
# --------------------------------------------------------------------------- #

def test_jit_vmap_and_float32(tmp_path):
    recs = records(tmp_path, [f"CIM6BL {DOUBLE} {CIM6_TAIL}", f"CIM6BL {SINGLE} {CIM6_TAIL}"])
    p, x, z, s0, _, where = initialised(Cim6bl, recs)
    v0 = jnp.asarray(where.v0)
    f32 = lambda d: {k: v.astype(jnp.complex64 if jnp.iscomplexobj(v) else jnp.float32)  # noqa
                     for k, v in d.items()}
    p32, x32, z32 = f32(p), f32(x), f32(z)
    rates = jax.jit(lambda p, x, z, v: Cim6bl.rates(p, x, LoadPorts(v, z))[1])
    assert max_rate(rates(p32, x32, z32, v0.astype(jnp.complex64))) < FLOAT32_TOL
    assert rates(p32, x32, z32, v0.astype(jnp.complex64))["w"].dtype == jnp.float32
    scales = jnp.asarray([1.0, 0.8, 0.5])  # a batch of voltages
    batched = jax.vmap(lambda a: Cim6bl.rates(p32, x32, LoadPorts(a * v0.astype(jnp.complex64),
                                                                z32))[1])
    one = {k: np.asarray(v) for k, v in Cim6bl.rates(p, x, LoadPorts(0.5 * v0, z))[1].items()}
    for k, v in batched(scales).items():
        np.testing.assert_allclose(np.asarray(v[2]), one[k], rtol=1e-4, atol=1e-3, err_msg=k)
    cur = jax.jit(Cim6bl.current)(p32, x32, z32, v0.astype(jnp.complex64))
    np.testing.assert_allclose(np.asarray(v0 * jnp.conj(cur)), s0, atol=1e-5)


# --------------------------------------------------------------------------- #
# 8. Whole simulator
# --------------------------------------------------------------------------- #

def test_flat_run_with_motor_loads(tmp_path):
    """Kundur's two loads as a double-cage CIM5BL and a single-cage CIM6BL: a 2 s run with
    no event stays at the power flow (float32 time loop)."""
    from conftest import andes_cases_dir
    from experiments.reference.andes_files import write_psse_dyr
    from jaxgrid.compile import compile_model
    from jaxgrid.io.raw import read_raw
    from jaxgrid.powerflow import PowerFlowOptions, solve
    from jaxgrid.simulate import simulate

    folder = andes_cases_dir() / "kundur"
    dyr = write_psse_dyr(str(folder / "kundur_full.dyr"), str(tmp_path / "kundur.dyr"))
    with open(dyr, "a") as f:
        f.write(f"7 'CIM5BL' '2' {DOUBLE} {CIM5_TAIL} /\n8 'CIM6BL' '1' {SINGLE} {CIM6_TAIL} /\n")
    case = read_raw(folder / "kundur.raw")
    model = compile_model(case, read_dyr(dyr),
                          pf=solve(case, PowerFlowOptions(enforce_q_limits=False)))
    assert sum("CIM" in line for line in model.notes) >= 2, model.notes
    traj = simulate(model, 2.0, 0.005, decimation=20)
    deviation = np.abs(np.asarray(traj.vm) - np.abs(model.v0)).max()
    assert not bool(traj.diverged) and deviation < 1e-4, f"flat run drifts {deviation:.2e} p.u."
