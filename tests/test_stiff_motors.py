"""Stiff induction-motor states: the exponential Heun step (`jaxgrid.steppers.exponential_heun`)
and the linearly implicit motor step (`jaxgrid.steppers.rosenbrock_heun`).

References: the φ functions against NumPy's complex128 exponential; the block solver against
NumPy's LU solve; the motor block's Jacobian against `jax.jacfwd` of one motor; the whole
step against
the same case run at a 1 ms step in float64 (plain Heun is stable there: the stalled
motor's slip rotation needs |λ·dt| = 0.38 < 2), on Kundur's two-area system shipped with
ANDES, with a constant-torque CIM5BL that stalls during a long fault.
"""
from __future__ import annotations

import numpy as np
import pytest

import jax
import jax.numpy as jnp

from jaxgrid.steppers import Solver, lu_solver, phi_functions

MOTOR = ("1  0.01 0.1  3.0  0.02  0.12  0 0  0 0 0 0  0  1.3  0.4  0 0 0  "  # VI = 0: no trip
         "0.0 0")  # D = 0: constant load torque, so the motor stalls in a long fault
FAULT = dict(bus=7, start=0.5, duration=0.3)
T_END = 2.0  # s
SAMPLE = 0.05  # s between compared samples


def test_phi_functions_match_the_exponential():
    """φ1 = (e^z − 1)/z and φ2 = (e^z − 1 − z)/z² in float32 against complex128, on both sides
    of the series threshold and along the stalled motor's |Im z| up to ωb·10 ms."""
    z = np.concatenate([np.array([0.0, 1e-6, -0.05 + 0.1j, 0.19j, 0.21, -0.21j]),
                        -np.linspace(0, 3, 7) - 1j * np.linspace(0, 3.8, 7)])
    phi1, phi2 = (np.asarray(f) for f in phi_functions(jnp.asarray(z, jnp.complex64)))
    zs = np.where(z == 0, 1.0, z)
    exact1 = np.where(z == 0, 1.0, np.expm1(zs) / zs)
    exact2 = np.where(z == 0, 0.5, (np.expm1(zs) - zs) / zs ** 2)
    # float32: a few roundings of the quotient's parts (6e-8 each) relative to |φ|
    np.testing.assert_allclose(phi1, exact1, rtol=2e-6)
    np.testing.assert_allclose(phi2, exact2, rtol=2e-6)


@pytest.fixture(scope="module")
def kundur_with_motor(tmp_path_factory):
    from conftest import andes_cases_dir
    from experiments.reference.andes_files import write_psse_dyr
    from jaxgrid.compile import CompileOptions, compile_model
    from jaxgrid.io.dyr import read_dyr
    from jaxgrid.io.raw import read_raw
    from jaxgrid.powerflow import PowerFlowOptions, solve

    folder = andes_cases_dir() / "kundur"
    tmp = tmp_path_factory.mktemp("kundur")
    dyr = write_psse_dyr(str(folder / "kundur_full.dyr"), str(tmp / "kundur.dyr"))
    with open(dyr, "a") as f:
        f.write(f"7 'CIM5BL' '2' {MOTOR} /\n")
    case = read_raw(folder / "kundur.raw")
    pf = solve(case, PowerFlowOptions(enforce_q_limits=False))
    return {precision: compile_model(case, read_dyr(dyr), CompileOptions(precision=precision),
                                     pf=pf)
            for precision in ("float32", "float64")}


def _run(model, dt, motor_step="exponential"):
    from jaxgrid.simulate import FaultEvent, simulate

    traj = simulate(model, T_END, Solver(dt, motor_step=motor_step), FaultEvent(**FAULT),
                    decimation=int(round(SAMPLE / dt)))
    speed = np.asarray(traj.final.loads[0]["w"])
    return np.asarray(traj.vm), speed, bool(traj.diverged)


@pytest.mark.parametrize("dt, motor_step, tolerance", [(0.005, "exponential", 1e-2),
                                                        (0.01, "exponential", 1e-2),
                                                        (0.025, "rosenbrock", 3e-2)])
def test_stalled_motor_at_large_steps(kundur_with_motor, dt, motor_step, tolerance):
    """The motor stalls (speed < 0.2 p.u. at the end in the reference); at 5 and 10 ms, where
    plain Heun grows a stalled motor's EMF by ≈ 1.9 and 4 per step, the float32 run stays
    finite and follows the 1 ms float64 run (exponential step), and so does the linearly
    implicit motor step at 25 ms: bus voltages within 1e-2 p.u. (3e-2 at 25 ms, 2.7e-2
    measured: the whole system's second-order error grows as dt²), the motor's final speed within 0.02 p.u. (the samples at the fault's start and
    clearing excluded: there the steps' event times differ by up to a step)."""
    vm_ref, speed_ref, diverged_ref = _run(kundur_with_motor["float64"], 0.001)
    assert not diverged_ref and speed_ref.max() < 0.2, speed_ref
    vm, speed, diverged = _run(kundur_with_motor["float32"], dt, motor_step)
    assert not diverged
    t = np.arange(vm.shape[0]) * SAMPLE
    events = (np.abs(t - FAULT["start"]) < 1.5 * dt) | (
        np.abs(t - FAULT["start"] - FAULT["duration"]) < 1.5 * dt)
    error = np.abs(vm - vm_ref)[~events]
    assert error.max() < tolerance, f"largest |dV| {error.max():.2e} p.u."
    np.testing.assert_allclose(speed, speed_ref, atol=0.02)


def test_block_solver_matches_numpy():
    """A batch of 5 × 5 systems I − γ·dt·J shaped like a motor block's (a rotation-dominated
    E' pair, a speed coupled to it): the unpivoted elimination against NumPy's pivoted LU
    solve, float64, to rounding (1e-12 relative)."""
    rng = np.random.default_rng(0)
    n = 16
    j = rng.normal(scale=5.0, size=(n, 5, 5))
    j[:, 0, 1], j[:, 1, 0] = 377.0, -377.0  # a stalled motor's slip rotation, 1/s
    a = np.eye(5) - 1.7 * 0.025 * j
    b = rng.normal(size=(n, 5))
    with jax.enable_x64(True):
        solve = lu_solver([[jnp.asarray(a[:, r, c]) for c in range(5)] for r in range(5)])
        got = np.stack([np.asarray(y) for y in solve([jnp.asarray(b[:, r]) for r in range(5)])],
                       1)
    np.testing.assert_allclose(got, np.linalg.solve(a, b[..., None])[..., 0], rtol=1e-12)


def test_block_jacobian_is_the_motors_own(kundur_with_motor):
    """`block_jacobian` seeds every block at once; for the motor of the test case it equals
    `jax.jacfwd` of its rates with respect to its five states at a depressed voltage
    (float64, to rounding)."""
    from jaxgrid.steppers import _implicit_blocks, block_jacobian
    from jaxgrid.models.base import LoadPorts

    model = kundur_with_motor["float64"]
    with jax.enable_x64(True):
        x = model.initial.replace(v=model.initial.v * 0.8)
        blocks = _implicit_blocks(model)
        got = np.array([[np.asarray(c) for c in row] for row in block_jacobian(model, x, blocks)])
        (g, names), = blocks
        group = model.loads[g]
        v = x.v[model.n_gen:][np.asarray(group.index)]

        def rates(values):
            states = {**x.loads[g], **dict(zip(names, values))}
            out = group.model.rates(group.params, states,
                                    LoadPorts(v=v, flags=x.load_flags[g]))[1]
            return jnp.stack([out[name] for name in names])

        want = jax.jacfwd(rates)(jnp.stack([x.loads[g][name] for name in names]))
    # want: (row, column, unit) after moving the unit axis last
    want = np.einsum("iuju->iju", np.asarray(want).reshape(5, -1, 5, want.shape[-1]))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
