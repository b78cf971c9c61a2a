"""jaxgrid.vecmath against NumPy's float64 functions.

Tolerances: float32 rounds to a relative 6e-8; the functions are allowed a few roundings
(the module docstring gives their measured errors), and jnp's own float32 functions are
held to the same bounds in the same test, so the bound is not looser than XLA's.
"""
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from experiments.bench import vecmath as bench_vecmath
from jaxgrid import vecmath


@pytest.fixture(scope="module")
def rng():
    return np.random.default_rng(7)


def test_sincos_matches_float64(rng):
    x = np.concatenate([np.linspace(-1000.0, 1000.0, 200_001), rng.normal(size=10_000) * 5,
                        [0.0, np.pi / 4, np.pi / 2, -np.pi, 1e-6]]).astype(np.float32)
    sin, cos = jax.jit(vecmath.sincos)(x)
    exact = x.astype(np.float64)
    assert np.max(np.abs(np.asarray(sin) - np.sin(exact))) < 2e-7
    assert np.max(np.abs(np.asarray(cos) - np.cos(exact))) < 2e-7
    assert np.max(np.abs(np.asarray(jnp.sin(x)) - np.sin(exact))) < 2e-7
    # small angles keep their relative accuracy (sin x ≈ x)
    assert abs(float(sin[-1]) - 1e-6) < 1e-13


def test_sincos_derivative_is_cos_and_minus_sin():
    x = jnp.linspace(-7.0, 7.0, 101, dtype=jnp.float32)
    d_sin = jax.vmap(jax.grad(lambda t: vecmath.sincos(t)[0]))(x)
    d_cos = jax.vmap(jax.grad(lambda t: vecmath.sincos(t)[1]))(x)
    np.testing.assert_allclose(d_sin, np.cos(np.asarray(x, np.float64)), atol=2e-7)
    np.testing.assert_allclose(d_cos, -np.sin(np.asarray(x, np.float64)), atol=2e-7)


def test_power_matches_float64(rng):
    base = np.concatenate([rng.uniform(0.0, 2.0, 20_000), [0.0, 0.0, 1.0]]).astype(np.float32)
    exponent = np.concatenate([rng.uniform(0.0, 6.0, 20_000), [0.0, 2.0, 3.7]]).astype(np.float32)
    got = np.asarray(jax.jit(vecmath.power)(base, exponent))
    exact = base.astype(np.float64) ** exponent.astype(np.float64)
    # exp(n·ln b) carries the rounding of n·ln b, |n ln b| <= 6·|ln 2e-5| here: 70 roundings
    np.testing.assert_allclose(got, exact, rtol=70 * 6e-8, atol=1e-30)
    assert got[-3] == 1.0 and got[-2] == 0.0  # 0 ** 0 = 1, 0 ** 2 = 0


def test_angle_matches_float64(rng):
    z = np.concatenate([rng.normal(size=100_000) + 1j * rng.normal(size=100_000),
                        np.exp(1j * np.linspace(-np.pi, np.pi, 10_001)),
                        [0, 1, -1, 1j, -1j, 1 + 1e-5j]]).astype(np.complex64)
    got = np.asarray(jax.jit(vecmath.angle)(z))
    exact = np.angle(z.astype(np.complex128))
    wrapped = np.abs(np.angle(np.exp(1j * (got - exact))))  # ±π are the same direction
    assert np.max(wrapped) < 4e-7
    assert got[-6] == 0.0 and abs(got[-2] + np.pi / 2) < 2e-7
    assert abs(got[-1] - 1e-5) < 1e-12  # a small angle keeps its relative accuracy


def test_float64_uses_jnp():
    with jax.enable_x64(True):
        x = jnp.asarray([0.3, 2.0], jnp.float64)
        sin, cos = vecmath.sincos(x)
        np.testing.assert_array_equal(sin, jnp.sin(x))
        np.testing.assert_array_equal(vecmath.angle(x + 1j * x), jnp.angle(x + 1j * x))


def test_bench_vecmath_times_every_function(tmp_path):
    out = tmp_path / "vecmath.json"
    bench_vecmath.main(["--elements", "64", "--out", str(out)])
    timings = json.loads(out.read_text())["ns_per_element"]
    assert set(timings) == set(bench_vecmath.FUNCTIONS)
    assert all(ns > 0 for ns in timings.values())
