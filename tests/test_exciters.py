"""Exciter models (`jaxgrid.models.exciters`): equilibrium at t = 0, limiters, data errors.

Parameters come from real DYR records where a file has the model (shared IEEE 39/300-bus and
ACTIVSg2000 files, ANDES's bundled Kundur and IEEE 14-bus files) and from hand-written records
otherwise. Behaviour checks use explicit Euler steps with the integrator's clipping to the
non-windup `limits`, so the expected numbers follow from the discrete update by hand.
"""
from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import SHARED_CASES, andes_cases_dir
from jaxgrid.io.dyr import read_dyr
from jaxgrid.models.base import ModelError
from jaxgrid.models.exciters import EXCITERS, ExciterPorts, ExciterStart
from jaxgrid.records import DyrRecord

# init and dynamics evaluate the same float64 expressions; what remains is round-off on
# derivatives of order KA·u/TA ~ 1e3 p.u./s.
EQUILIBRIUM_TOL = 1e-9
# Euler trajectories are compared with their own closed-form discrete solution.
DISCRETE_TOL = 1e-12

N_CONS = {"IEEET1": 14, "IEEEX1": 16, "EXDC1": 16, "EXDC2": 16, "ESDC1A": 16, "ESDC2A": 16,
          "SEXS": 6, "SCRX": 8, "ESST3A": 21, "EXST1": 12, "ESST1A": 18, "EXAC1": 17,
          "EXAC2": 23, "ESAC1A": 19, "ESAC6A": 23, "EXPIC1": 24}
ACTIVSG = ("ESDC1A", "ESDC2A", "SCRX", "EXAC1", "EXAC2", "ESAC1A", "ESAC6A", "EXPIC1")

# Typical values; the second unit of each exercises the zero-time-constant bypasses.
HAND = {
    # TR KA TA TB TC VRMAX VRMIN KE TE KF TF1 Switch E1 SE1 E2 SE2
    "IEEEX1": [(0.02, 100, 0.05, 10, 1, 6, -6, 1, 0.5, 0.04, 1, 0, 2.8, 0.08, 3.7, 0.33),
               (0, 40, 0, 0, 0, 5, -5, 0, 0.9, 0, 0, 0, 0, 0, 0, 0)],
    # TA/TB TB K TE EMIN EMAX
    "SEXS": [(0.1, 10, 100, 0.05, 0, 4), (0.2, 0, 50, 0, -1, 5)],
    # UEL VOS TR VIMAX VIMIN TC TB TC1 TB1 KA TA VAMAX VAMIN VRMAX VRMIN KC KF TF KLR ILR:
    # GridPACK's 300-bus units with a second lead-lag, rate feedback and the field-current
    # limiter acting at t = 0 (XadIfd0 = EFD0 > ILR); then every time constant zero
    "ESST1A": [(1, 1, 0.02, 0.5, -0.5, 0.51, 2.01, 0.1, 0.05, 178.9, 0.029, 999, -999, 4.48,
                -1.79, 0.11, 0.02, 1.0, 1.0, 1.2),
               (3, 2, 0, 999, -999, 0, 0, 0, 0, 100, 0, 999, -999, 5, -4, 0.05, 0, 0, 0, 0)],
}


def hand(model: str, cons, line: int = 1, source: str = "hand.dyr") -> DyrRecord:
    return DyrRecord(model=model, bus=1, device_id="1", cons=tuple(float(c) for c in cons),
                     icons=(), header=(), record_type=model, line=line, source=source)


def andes_records(tmp_path: Path, case: str, model: str) -> tuple[DyrRecord, ...]:
    """Records of an ANDES-bundled DYR file, without its 'Toggle' lines (ANDES events)."""
    src = andes_cases_dir() / case
    path = tmp_path / src.name
    path.write_text("".join(line for line in src.read_text().splitlines(keepends=True)
                            if "Toggle" not in line))
    return read_dyr(path).by_model(model)


@functools.cache
def activsg_records():
    """ACTIVSg2000's composite-load DYR file, read once."""
    return read_dyr(SHARED_CASES / "activsg2000" / "ACTIVSg2000_dyn_cmld_zone3_v1.dyr")


def real_records(name: str, tmp_path: Path) -> tuple[DyrRecord, ...]:
    """The records the equilibrium test uses for model `name`."""
    if name == "IEEET1":
        return (read_dyr(SHARED_CASES / "ieee39" / "IEEE39bus_3AC.dyr").by_model(name)
                + activsg_records().by_model(name))
    if name == "EXDC1":
        return read_dyr(SHARED_CASES / "ieee300" / "IEEE300_genrou_exdc1_tgov1_zone1ac.dyr"
                        ).by_model(name)
    if name == "EXDC2":  # E1 = SE1 = 0: no saturation
        return andes_records(tmp_path, "kundur/kundur_full.dyr", name)
    if name in ACTIVSG:
        return activsg_records().by_model(name)
    if name in ("ESST3A", "EXST1"):
        return andes_records(tmp_path, "ieee14/ieee14.dyr", name)
    return tuple(hand(name, cons) for cons in HAND[name])


def inputs(ec, xadifd) -> ExciterPorts:
    ec = jnp.asarray(ec, dtype=jnp.float64)
    return ExciterPorts(ec=ec, vt=ec * jnp.exp(0.3j), it=jnp.full(ec.shape, 0.8 - 0.2j),
                        xadifd=jnp.asarray(xadifd, dtype=jnp.float64), dw=jnp.zeros_like(ec),
                        vs=jnp.zeros_like(ec))


def start(model, records, efd0, ec0=1.0):
    """(p, x, inputs) at equilibrium for efd0 (one value or one per unit), Ec = ec0."""
    p = model.prepare(model.read(records))
    n = len(records)
    efd0 = jnp.broadcast_to(jnp.asarray(efd0, dtype=jnp.float64), (n,))
    inp = inputs(jnp.full((n,), ec0), efd0)
    p, x, *_ = model.init(p, ExciterStart(efd0, inp))
    return p, x, inp


def simulate(model, p, x, inp, dt: float, n_steps: int):
    """Explicit Euler; states clipped to `limits` after each update. Returns (EFD, states)
    per step, stacked: EFD before and states after the step."""
    limits = model.limits(p)

    def step(x, _):
        efd, dx = model.rates(p, x, inp)
        x = {k: x[k] + dt * dx[k] for k in x}
        x = {k: jnp.clip(v, *limits[k]) if k in limits else v for k, v in x.items()}
        return x, (efd, x)

    return jax.lax.scan(step, x, None, length=n_steps)[1]


# --------------------------------------------------------------------------- #
# Equilibrium at t = 0
# --------------------------------------------------------------------------- #

@pytest.mark.parametrize("name", sorted(EXCITERS))
def test_equilibrium(name, tmp_path):
    model = EXCITERS[name]
    assert len(model.cons) == N_CONS[name], f"{name}: {len(model.cons)} CONs"
    records = real_records(name, tmp_path)
    assert records, f"no {name} records"
    n = len(records)
    with jax.enable_x64(True):
        efd0 = jnp.linspace(1.5, 2.2, n)  # above 2.38 one ACTIVSg2000 IEEET1 cannot hold EFD0
        p = model.prepare(model.read(records))
        inp = inputs(jnp.linspace(0.98, 1.04, n), efd0)
        p, x, *_ = model.init(p, ExciterStart(efd0, inp))
        assert set(x) == set(model.states), f"{name}: init states {sorted(x)}"
        violations = {k: int(np.sum(v)) for k, v in model.init_violations(p, x).items()}
        assert not any(violations.values()), f"{name}: limits violated at t = 0: {violations}"

        def total_rate(ec):
            return sum(jnp.sum(d) for d in model.rates(p, x, inp._replace(ec=ec))[1].values())

        (efd, dx), grad = jax.jit(lambda ec: (model.rates(p, x, inp._replace(ec=ec)),
                                              jax.grad(total_rate)(ec)))(inp.ec)
        assert set(dx) == set(model.states), f"{name}: derivative keys {sorted(dx)}"
        for state, d in dx.items():
            worst = float(jnp.max(jnp.abs(d)))
            assert worst < EQUILIBRIUM_TOL, f"{name}: d{state}/dt = {worst:.3g} at t = 0"
        err = float(jnp.max(jnp.abs(efd - efd0)))
        assert err < EQUILIBRIUM_TOL, f"{name}: EFD differs from EFD0 by {err:.3g}"
        assert bool(jnp.all(jnp.isfinite(grad))), f"{name}: gradient wrt Ec not finite: {grad}"


# --------------------------------------------------------------------------- #
# Behaviour
# --------------------------------------------------------------------------- #

def lag_stops_at_limit(model, record, state: str, target: float, limit: float, hit: int):
    """From rest at EFD0 = 2 (the state at 2), Ec 1.0 → 0.9: explicit Euler (dt = 1 ms) moves
    `state` as the lag of time constant 0.05 s toward `target`, x_n = target −
    (target − 2)·(1 − dt/0.05)^n, until that would pass `limit` (after `hit` + 1 steps);
    then it stays at `limit` with a zero derivative. Returns (p, EFD, trajectory)."""
    dt, n_steps = 1e-3, 200
    with jax.enable_x64(True):
        p, x, inp = start(model, [record], 2.0)
        stepped = inp._replace(ec=inp.ec - 0.1)
        efd, traj = simulate(model, p, x, stepped, dt, n_steps)
        values = np.asarray(traj[state][:, 0])
        free = target - (target - 2.0) * (1.0 - dt / 0.05) ** np.arange(1, n_steps + 1)
        reached = int(np.argmax(free > limit))
        assert reached == hit, f"{state} reaches its limit after {reached + 1} steps"
        np.testing.assert_allclose(values[:hit], free[:hit], rtol=0, atol=DISCRETE_TOL,
                                   err_msg=f"{state} before the limit: lag toward {target}")
        assert np.all(values[hit:] == limit), f"{state} after the limit: {values[hit:hit + 5]}"
        _, dx = model.rates(p, {k: v[-1] for k, v in traj.items()}, stepped)
        assert float(dx[state][0]) == 0.0, f"d{state}/dt = {dx[state]} at the limit (frozen)"
    return p, np.asarray(efd[:, 0]), values


def test_ieeet1_regulator_stops_at_vrmax():
    # TR 0 KA 50 TA 0.05 VRMAX 5 VRMIN -5 KE 1 TE 0.5 KF 0 TF 0 Switch 0, no saturation:
    # VR obeys TA dVR/dt = KA·(Vref − Ec) − VR alone. EFD0 = 2 gives VR0 = 2, Vref = 1.04;
    # Ec 1.0 → 0.9 drives VR toward 50·0.14 = 7 until it passes VRMAX = 5 (n = 46).
    record = hand("IEEET1", (0, 50, 0.05, 5, -5, 1, 0.5, 0, 0, 0, 0, 0, 0, 0))
    p, _, _ = lag_stops_at_limit(EXCITERS["IEEET1"], record, "vr", 7.0, 5.0, 45)
    assert abs(float(p["vref"][0]) - 1.04) < DISCRETE_TOL, f"Vref = {p['vref']}"


def test_sexs_steady_state_gain():
    # K = 100: a −0.01 step of Ec moves EFD by +1.0 in steady state (2 → 3 < EMAX = 4).
    # The TE = 0, TB = 1 unit jumps at once by K·(TA/TB)·0.01 = 0.1 (lead-lag high-frequency
    # gain) before the lag state follows.
    model = EXCITERS["SEXS"]
    records = [hand("SEXS", (0.1, 1, 100, 0.05, 0, 4)), hand("SEXS", (0.1, 1, 100, 0, 0, 4))]
    with jax.enable_x64(True):
        p, x, inp = start(model, records, 2.0)
        stepped = inp._replace(ec=inp.ec - 0.01)
        efd, _ = model.rates(p, x, stepped)
        assert abs(float(efd[1]) - 2.1) < DISCRETE_TOL, f"EFD right after the step: {efd}"
        efd, _ = simulate(model, p, x, stepped, 1e-3, 25_000)
        final = np.asarray(efd[-1])
        np.testing.assert_allclose(final, 3.0, rtol=0, atol=1e-6,
                                   err_msg="EFD must settle at EFD0 + K·0.01")


def test_exdc2_ceiling_scales_with_ec():
    # Same data for IEEEX1 and EXDC2 (no saturation, KF = 0): after Ec drops to 0.8 the
    # regulator saturates at VRMAX = 3 (IEEEX1) or VRMAX·Ec = 2.4 (EXDC2). VR is read back
    # from TE·dEFD/dt + KE·EFD.
    cons = (0, 100, 0.02, 0, 0, 3, -3, 1, 0.5, 0, 0, 0, 0, 0, 0, 0)
    ceilings = {}
    with jax.enable_x64(True):
        for name in ("IEEEX1", "EXDC2"):
            model = EXCITERS[name]
            p, x, inp = start(model, [hand(name, cons)], 1.5)
            stepped = inp._replace(ec=inp.ec * 0.8)
            _, traj = simulate(model, p, x, stepped, 1e-3, 200)
            last = {k: v[-1] for k, v in traj.items()}
            _, dx = model.rates(p, last, stepped)
            ceilings[name] = float(0.5 * dx["efd"][0] + last["efd"][0])
    assert abs(ceilings["IEEEX1"] - 3.0) < DISCRETE_TOL, f"IEEEX1 ceiling {ceilings}"
    assert abs(ceilings["EXDC2"] - 2.4) < DISCRETE_TOL, f"EXDC2 ceiling {ceilings}"


def test_exdc2_init_violation_uses_ec():
    # VR0 = KE·EFD0 = 2.85 fits VRMAX = 3 but not VRMAX·Ec0 = 2.7 at Ec0 = 0.9.
    cons = (0, 100, 0.02, 0, 0, 3, -3, 1, 0.5, 0, 0, 0, 0, 0, 0, 0)
    with jax.enable_x64(True):
        flagged = {}
        for name in ("IEEEX1", "EXDC2"):
            model = EXCITERS[name]
            p, x, _ = start(model, [hand(name, cons)], 2.85, ec0=0.9)
            flagged[name] = bool(model.init_violations(p, x)["vr"][0])
    assert flagged == {"IEEEX1": False, "EXDC2": True}, f"VR0 flagged: {flagged}"


def test_ieeet1_real_unit_ceiling(tmp_path):
    # ACTIVSg2000 bus 8129: KE = 0, VRMAX = 1, saturation (1.7491, 0.1303), (2.3321, 0.3943),
    # so r = 0.49784, A = 1.17111, B = 0.68221 and VR0 = B·(EFD0 − A)²: 1.2047 at EFD0 = 2.5
    # (above VRMAX: reported), 1.0 at EFD0 = 2.3818.
    model = EXCITERS["IEEET1"]
    record = [r for r in activsg_records().by_model("IEEET1") if r.bus == 8129]
    with jax.enable_x64(True):
        p, x, _ = start(model, record * 2, jnp.array([2.38, 2.5]))
        flagged = np.asarray(model.init_violations(p, x)["vr"]).tolist()
    assert abs(float(x["vr"][1]) - 1.20474) < 1e-5, f"VR0 = {x['vr']}"
    assert flagged == [False, True], f"VR0 = {x['vr']} flagged {flagged}"


def test_esst3a_input_limit_violation(tmp_path):
    # IEEE 14-bus ESST3A (KM 8, KA 20, KG 1, VGMAX 3.86, VIMAX 0.2): VB0 ≈ 3.87 here, so
    # EFD0 = 6 needs Vi0 = (6/VB0/8 + 3.86)/20 ≈ 0.203 > VIMAX; EFD0 = 2 needs ≈ 0.103.
    model = EXCITERS["ESST3A"]
    record = andes_records(tmp_path, "ieee14/ieee14.dyr", "ESST3A")[0]
    with jax.enable_x64(True):
        p, x, _ = start(model, [record, record], jnp.array([2.0, 6.0]))
        found = {k: np.asarray(v).tolist() for k, v in model.init_violations(p, x).items()}
    assert found == {"vr": [False, False], "vm_inner": [False, False], "vi": [False, True]}, found


def test_esst1a_input_and_va_limits():
    # TR 0, VIMAX 0.05, KA 100, TA 0.05, VAMAX 4, lead-lags bypassed, KF = KLR = 0: EFD0 = 2
    # gives VA0 = 2 and Vi0 = 0.02. Ec 1.0 → 0.9 makes the error 0.12, clipped to VIMAX, so VA
    # heads for KA·VIMAX = 5 (not 12) until it passes VAMAX = 4 (n = 55); EFD = VA, inside the
    # ceiling Ec·VRMAX = 4.5.
    record = hand("ESST1A", (1, 1, 0, 0.05, -0.05, 0, 0, 0, 0, 100, 0.05, 4, -4, 5, -5, 0, 0,
                             0, 0, 0))
    _, efd, va = lag_stops_at_limit(EXCITERS["ESST1A"], record, "va", 5.0, 4.0, 54)
    np.testing.assert_allclose(efd[1:], va[:-1], rtol=0, atol=DISCRETE_TOL)


def test_esst1a_field_current_limiter_and_ceiling():
    # KLR 2, ILR 2.5: EFD = clip(VA − 2·max(XadIfd − 2.5, 0), Ec·VRMIN, Ec·VRMAX − KC·XadIfd)
    # at once (algebraic). At rest EFD0 = 2 with XadIfd 2 (limiter off): VA = 2. XadIfd 3
    # takes 1.0 off: EFD 1.0; at Ec 0.5 and XadIfd 2 the ceiling 0.5·5 − 0.2·2 = 2.1 holds 2,
    # at Ec 0.4 it is 1.6; the floor Ec·VRMIN = −2 holds a VA of −3.
    model = EXCITERS["ESST1A"]
    record = hand("ESST1A", (2, 1, 0, 9, -9, 0, 0, 0, 0, 100, 0.05, 9, -9, 5, -5, 0.2, 0, 0,
                             2.0, 2.5))
    with jax.enable_x64(True):
        p, x, inp = start(model, [record] * 4, 2.0)
        x = dict(x, va=jnp.array([2.0, 2.0, 2.0, -3.0]))
        efd, _ = model.rates(p, x, inputs([1.0, 0.5, 0.4, 0.4], [3.0, 2.0, 2.0, 2.0]))
    np.testing.assert_allclose(np.asarray(efd), [1.0, 2.0, 1.6, -2.0], rtol=0,
                               atol=DISCRETE_TOL, err_msg="ESST1A limiter and output limits")


def test_exst1_output_ceiling():
    # EFD = clip(VR, Ec·VRMIN, Ec·VRMAX − KC·XadIfd) = clip(±10, −3.6, 4.1) at Ec 0.9, XadIfd 2.
    # TR VIMAX VIMIN TC TB KA TA VRMAX VRMIN KC KF TF
    model = EXCITERS["EXST1"]
    records = [hand("EXST1", (0, 99, -99, 0, 0, 50, 0.02, 5, -4, 0.2, 0, 0))] * 2
    with jax.enable_x64(True):
        p, x, _ = start(model, records, 2.0)
        x = dict(x, vr=jnp.array([10.0, -10.0]))
        efd, _ = model.rates(p, x, inputs([0.9, 0.9], [2.0, 2.0]))
    np.testing.assert_allclose(np.asarray(efd), [4.1, -3.6], rtol=0, atol=DISCRETE_TOL,
                               err_msg="EXST1 output limits")


# --------------------------------------------------------------------------- #
# Data errors
# --------------------------------------------------------------------------- #

IEEET1_OK = (0, 50, 0.05, 5, -5, 1, 0.5, 0.04, 1, 0, 2.8, 0.08, 3.7, 0.33)
IEEEX1_OK = HAND["IEEEX1"][0]
EXST1_OK = (0.02, 99, -99, 0, 0.02, 50, 0.02, 9999, -9999, 0, 0.01, 1)
ESST1A_OK = HAND["ESST1A"][0]


def edit(cons, **changes):
    """cons with CON(j) replaced, given as c<j>=value (1-based)."""
    out = list(cons)
    for key, value in changes.items():
        out[int(key[1:]) - 1] = value
    return out


@pytest.mark.parametrize("name, cons, pattern", [
    ("IEEET1", edit(IEEET1_OK, c10=1), r"CON\(10\) SWITCH = 1: only 0 .*unverified"),
    ("IEEET1", edit(IEEET1_OK, c3=-0.1), r"CON\(3\) TA = -0.1 s: must lie in"),
    ("IEEET1", edit(IEEET1_OK, c7=0), r"CON\(7\) TE = 0 s: must be > 0"),
    ("IEEET1", edit(IEEET1_OK, c11=2, c12=0.5, c13=4, c14=0.25),
     r"CON\(11\) E1, CON\(12\) SE1, CON\(13\) E2, CON\(14\) SE2 = 2, 0.5, 4, 0.25: no "
     r"quadratic saturation curve"),
    ("IEEET1", edit(IEEET1_OK, c13=2.8), r"SE2 = 2.8, 0.08, 2.8, 0.33: no quadratic"),
    ("IEEEX1", edit(IEEEX1_OK, c12=2), r"CON\(12\) SWITCH = 2"),
    ("IEEEX1", edit(IEEEX1_OK, c11=0), r"CON\(11\) TF1 = 0 s with KF = 0.04: .*must be > 0"),
    ("EXDC2", edit(IEEEX1_OK, c6=-7), r"CON\(7\) VRMIN, CON\(6\) VRMAX: VRMIN = -6 > VRMAX = -7"),
    ("SEXS", (0.1, 10, 100, 0.05, 5, 4), r"CON\(5\) EMIN, CON\(6\) EMAX: EMIN = 5 > EMAX = 4"),
    ("ESST3A", (0.02, 0.2, -0.2, 8, 1, 5, 20, 0, 99, -99, 1, 3.67, 0.435, 5.48, 0.01, 0.0098,
                3.86, 3.33, 0, 99, 0), r"CON\(19\) TM = 0 s: must be > 0"),
    ("EXST1", edit(EXST1_OK, c7=0), r"CON\(7\) TA = 0 s with KF = 0.01: .*algebraic loop"),
    # ESST1A values (ICONs UEL, VOS first; CON(j) is value j + 2)
    ("ESST1A", edit(ESST1A_OK, c1=4), r"ICON UEL = 4: PSS/E defines 1, 2, 3; other codes are "
                                      r"not supported"),
    ("ESST1A", edit(ESST1A_OK, c2=0), r"ICON VOS = 0: PSS/E defines 1, 2"),
    ("ESST1A", edit(ESST1A_OK, c11=0), r"CON\(9\) TA = 0 s with KF = 0.02: .*algebraic loop"),
    ("ESST1A", edit(ESST1A_OK, c12=-1000),
     r"CON\(11\) VAMIN, CON\(10\) VAMAX: VAMIN = -999 > VAMAX = -1000"),
])
def test_bad_data_names_file_line_and_con(name, cons, pattern):
    record = hand(name, cons, line=7, source="bad.dyr")
    with pytest.raises(ModelError, match=rf"^bad\.dyr:7: {name} at bus 1 .*(?:{pattern})"):
        EXCITERS[name].read([record])


# --------------------------------------------------------------------------- #
# Models added for ACTIVSg2000 (SCRX, ESDC2A, EXAC1, EXAC2, ESAC1A, ESAC6A, EXPIC1):
# known answers by hand; ANDES trajectories for EXAC1, EXAC2, ESAC1A, ESDC2A in
# tests/test_simulate.py (ieee14_ac)
# --------------------------------------------------------------------------- #

def test_rectifier_source_inverts_the_rectifier_on_every_branch():
    # IN = KC·XadIfd/VE across FEX's three branches (0.2, 0.6, 0.9) and VE <= 0 (EFD 0)
    from jaxgrid.models.exciters import rectifier_output, rectifier_source
    with jax.enable_x64(True):
        ve = jnp.array([2.0, 2.0, 2.0])
        kc_ifd = ve * jnp.array([0.2, 0.6, 0.9])
        efd = rectifier_output(ve, kc_ifd)
        np.testing.assert_allclose(np.asarray(efd), [2 * (1 - 0.577 * 0.2),
                                                     2 * np.sqrt(0.75 - 0.36),
                                                     2 * 1.732 * 0.1], rtol=1e-14)
        np.testing.assert_allclose(np.asarray(rectifier_source(efd, kc_ifd)), 2.0, rtol=1e-12)
        assert float(rectifier_output(jnp.array([-0.1]), jnp.array([0.3]))[0]) == 0.0


def test_saturation_points_in_either_order_give_one_curve():
    # ACTIVSg2000 EXAC2 at bus 5365 writes E1 = 4.6223 > E2 = 3.4667: the curve through the
    # two points is the same whichever is first; bus 5051's points (S·E falling with E)
    # give A = 5.672 above both: no saturation there, noted
    model = EXCITERS["EXAC2"]
    by_bus = {r.bus: r for r in activsg_records().by_model("EXAC2")}
    swapped = list(by_bus[5365].cons)
    swapped[19:23] = [swapped[21], swapped[22], swapped[19], swapped[20]]
    p = model.prepare(model.read([by_bus[5365], hand("EXAC2", swapped), by_bus[5051]]))
    np.testing.assert_allclose(p["sat_a"][:2], p["sat_a"][0], rtol=1e-12)
    np.testing.assert_allclose(p["sat_b"][:2], p["sat_b"][0], rtol=1e-12)
    assert p["sat_a"][2] == pytest.approx(5.672, abs=1e-3)
    notes = model.notes(p, ("5365", "hand", "5051"))
    assert notes == ["5365: saturation points E1 = 4.6223 > E2 = 3.4667: read in either order "
                     "(PSS/E's two-point formula)",
                     "5051: saturation points E1 = 4.5931 > E2 = 3.4448: read in either order "
                     "(PSS/E's two-point formula)",
                     "5051: the saturation curve through (4.5931, 0.0022), (3.4448, 0.0125) has "
                     "A = 5.672 above a point (S·E does not grow with E): read as PSS/E's "
                     "formula gives it, no saturation below 5.672"], notes


def test_scrx_bus_fed_and_negative_current():
    # TA/TB 0.1 TB 10 K 100 TE 0 EMIN -4 EMAX 5 CSWITCH rc/rfd: EFD0 = 2 at Ec = 1 holds
    # E0 = 2 bus-fed; Ec 0.8 scales the output to 0.8·E (E jumps by K·TA/TB·0.2 = 2 at
    # once: 0.8·4 = 3.2); solid-fed E = 4; rc/rfd 5 with XadIfd = −0.1 gives 0.5.
    model = EXCITERS["SCRX"]
    records = [hand("SCRX", (0.1, 10, 100, 0, -4, 5, c, r)) for c, r in ((0, 0), (1, 0), (0, 5))]
    with jax.enable_x64(True):
        p, x, inp = start(model, records, 2.0)
        efd, _ = model.rates(p, x, inputs([0.8, 0.8, 0.8], [2.0, 2.0, -0.1]))
    np.testing.assert_allclose(np.asarray(efd), [3.2, 4.0, 0.5], rtol=0, atol=DISCRETE_TOL)


def test_exac2_field_current_limiter_gates_vr():
    # TR 0 TB 0 TC 0 KA 400 TA 0.02 VAMAX 8 VAMIN -8 KB 25 VRMAX 105 VRMIN -95 TE 0.6 KL 1
    # KH 1 KF 0 TF 1 KC 0 KD 0 KE 1 VLR 4.4, no saturation: VR = clip(KB·min(VA − KH·VFE,
    # KL·(VLR − VFE)), ±VR): with VFE = VE = 2 (KC = KD = 0) and VA = 8 the limiter path
    # 1·(4.4 − 2) = 2.4 < 6 wins: VR = 60, TE·dVE/dt = 60 − 2.
    cons = (0, 0, 0, 400, 0.02, 8, -8, 25, 105, -95, 0.6, 1, 1, 0, 1, 0, 0, 1, 4.4, 0, 0, 0, 0)
    model = EXCITERS["EXAC2"]
    with jax.enable_x64(True):
        p, x, inp = start(model, [hand("EXAC2", cons)], 2.0)
        assert float(x["va"][0]) == pytest.approx(2 / 25 + 2, abs=DISCRETE_TOL)
        _, dx = model.rates(p, dict(x, va=jnp.array([8.0])), inp)
    assert float(dx["ve"][0]) == pytest.approx((60 - 2) / 0.6, abs=1e-9)


def test_esac6a_ceiling_scales_with_ec_and_va_is_non_windup():
    # TR 0 KA 100 TA 1 TK 0 TB 0 TC 0 VAMAX 4 VAMIN -4 VRMAX 3 VRMIN -3 TE 1 VFELIM 10 KH 0
    # VHMAX 0 TH 0 TJ 0 KC 0 KD 0 KE 1, no saturation: VR = clip(VA, ±3·Ec). EFD0 = 2 holds
    # VE = VFE = VA = 100·xa = 2. At Ec 0.5 the ceiling 1.5 holds VR at once (TE·dVE/dt =
    # 1.5 − 2) while xa heads for the error 0.52; once VA = 4 (VAMAX) xa stops (non-windup).
    cons = (0, 100, 1, 0, 0, 0, 4, -4, 3, -3, 1, 10, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0)
    model = EXCITERS["ESAC6A"]
    with jax.enable_x64(True):
        p, x, inp = start(model, [hand("ESAC6A", cons)], 2.0)
        stepped = inp._replace(ec=inp.ec * 0.5)
        _, dx = model.rates(p, x, stepped)
        assert float(dx["ve"][0]) == pytest.approx(1.5 - 2.0, abs=DISCRETE_TOL)
        assert float(dx["xa"][0]) == pytest.approx(0.52 - 0.02, abs=DISCRETE_TOL)
        _, dx = model.rates(p, dict(x, xa=jnp.array([0.04])), stepped)  # VA = 4
    assert float(dx["xa"][0]) == 0.0, "the KA block's state must stop at VAMAX"


def test_expic1_pi_integrates_and_stops_at_vr1():
    # TR 0 KA 3 TA1 1 VR1 1 VR2 -0.87, filters and feedback off, VRMAX 1 VRMIN -0.87, EFDMAX
    # 6.5 EFDMIN 0, KE 0 TE 0, KP 5 KI 0 KC 0.08 (ACTIVSg2000's pattern): VB = KP·Ec·FEX(IN)
    # with IN = 0.08·2/5, EFD0 = 2 holds VR0 = EFD0/VB. An error u = 0.02 (Ec 0.98) makes
    # dxi/dt = KA·u = 0.06 and VA = xi + KA·TA1·u; at VA = VR1 the integral stops.
    cons = (0, 3, 1, 1, -0.87, 0, 0, 0, 1, -0.87, 0, 1, 0, 6.5, 0, 0, 0, 1, 0, 1.2, 0, 5, 0,
            0.08)
    model = EXCITERS["EXPIC1"]
    with jax.enable_x64(True):
        p, x, inp = start(model, [hand("EXPIC1", cons)], 2.0)
        vb0 = 5 * 1.0 * (1 - 0.577 * 0.08 * 2 / 5)
        assert float(x["xi"][0]) == pytest.approx(2 / vb0, abs=DISCRETE_TOL)
        stepped = inputs([0.98], [2.0])
        efd, dx = model.rates(p, x, stepped)
        assert float(dx["xi"][0]) == pytest.approx(0.06, abs=DISCRETE_TOL)
        vb = 5 * 0.98 * (1 - 0.577 * 0.08 * 2 / (5 * 0.98))
        assert float(efd[0]) == pytest.approx(vb * (2 / vb0 + 0.06), abs=DISCRETE_TOL)
        _, dx = model.rates(p, dict(x, xi=jnp.array([1.0])), stepped)
    assert float(dx["xi"][0]) == 0.0, "the PI's integral must stop at VR1"


def test_esst1a_vos_places_the_stabilizer_signal():
    # TR 0, VIMAX 0.05, lead-lags bypassed, KA 100, TA 0.05, KF = KLR = 0; EFD0 = 2 (VA0 2,
    # Vi0 0.02). VOS 2: VS adds to EFD at once (2.1), VA stays at rest; VOS 1: VS joins the
    # voltage error, 0.02 + 0.1 clipped to VIMAX, and VA heads for KA·0.05 = 5.
    base = (0.0, 0.05, -0.05, 0, 0, 0, 0, 100, 0.05, 9, -9, 5, -5, 0, 0, 0, 0, 0)
    model = EXCITERS["ESST1A"]
    records = [hand("ESST1A", (1, vos) + base) for vos in (1, 2)]
    with jax.enable_x64(True):
        p, x, inp = start(model, records, 2.0)
        efd, dx = model.rates(p, x, inp._replace(vs=jnp.full(2, 0.1)))
    np.testing.assert_allclose(np.asarray(efd), [2.0, 2.1], rtol=0, atol=DISCRETE_TOL)
    # VOS 1: VA heads for KA·clip(0.02 + 0.1, ±0.05) = 5 at rate (5 − 2)/TA; VOS 2: at rest
    np.testing.assert_allclose(np.asarray(dx["va"]), [(5 - 2) / 0.05, 0.0], rtol=0,
                               atol=1e-9)
