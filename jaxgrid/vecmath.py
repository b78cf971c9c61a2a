"""Elementary functions that XLA:CPU vectorises, for the integration step's device code.

XLA:CPU evaluates `jnp.sin`, `jnp.cos`, `jnp.power` and `jnp.angle` one element at a
time: 1.5–14 ns per float32 element on the development machine, against 0.05 for a
multiply and 0.3 for `jnp.exp`, which it vectorises (`experiments.bench.vecmath`;
docs/performance.md). The step's rotor-frame rotations and load characteristics therefore use:
- `sincos`: the argument reduced by π/2 in three parts (Cody–Waite), then the Cephes
  single-precision minimax polynomials on [−π/4, π/4]: 0.6–0.9 ns per element for both.
  Largest error against float64 over |x| ≤ 1000 rad: 9e-8 (jnp.sin: 3e-8; float32 rounding
  is 6e-8). float64 arguments use jnp.sin and jnp.cos.
- `power`: exp(exponent·log(base)) for base >= 0: about 1 ns per element, relative error
  about |exponent·ln base| float32 roundings.
- `angle`: the argument of a complex number by the Cephes single-precision arctangent on
  [0, tan(π/8)] after reducing the ratio of the parts to [0, 1]: 0.5 ns per element.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

# π/2 = PIO2_A + PIO2_B + PIO2_C, the first two exact in float32 (few significant bits)
PIO2_A, PIO2_B, PIO2_C = 1.5703125, 4.837512969970703125e-4, 7.54978995489188216e-8
SIN_COEFFS = (-1.6666654611e-1, 8.3321608736e-3, -1.9515295891e-4)  # r³, r⁵, r⁷
COS_COEFFS = (4.166664568298827e-2, -1.388731625493765e-3, 2.443315711809948e-5)  # r⁴, r⁶, r⁸
ATAN_COEFFS = (-3.33329491539e-1, 1.99777106478e-1, -1.38776856032e-1, 8.05374449538e-2)
TAN_PI_8 = 0.4142135623730950


def _poly(z, coeffs):
    out = coeffs[-1]
    for c in reversed(coeffs[:-1]):
        out = c + z * out
    return out


@jax.custom_jvp
def sincos(x):
    """(sin x, cos x) of a real array x (radians), same shape and dtype."""
    if x.dtype == jnp.float64:
        return jnp.sin(x), jnp.cos(x)
    k = jnp.round(x * np.float32(2 / np.pi))
    r = ((x - k * PIO2_A) - k * PIO2_B) - k * PIO2_C
    z = r * r
    s = r + r * z * _poly(z, SIN_COEFFS)
    c = 1.0 - 0.5 * z + z * z * _poly(z, COS_COEFFS)
    quadrant = k.astype(jnp.int32) & 3  # x = r + quadrant·π/2 (mod 2π)
    sin = jnp.select([quadrant == 0, quadrant == 1, quadrant == 2], [s, c, -s], -c)
    cos = jnp.select([quadrant == 0, quadrant == 1, quadrant == 2], [c, -s, -c], s)
    return sin, cos


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    sin, cos = sincos(x)
    return (sin, cos), (cos * dx, -sin * dx)


def power(base, exponent):
    """base ** exponent for base >= 0 (arrays or scalars, broadcast), 0 ** 0 = 1.

    The gradient with respect to base is 0 where base = 0.
    """
    positive = base > 0
    safe = jnp.where(positive, base, 1.0)
    return jnp.where(positive, jnp.exp(exponent * jnp.log(safe)),
                     jnp.where(exponent == 0, 1.0, 0.0))


def angle(z):
    """The argument of complex z in (−π, π], radians, real dtype of z; angle(0) = 0."""
    re, im = jnp.real(z), jnp.imag(z)
    if re.dtype == jnp.float64:
        return jnp.angle(z)
    a, b = jnp.abs(re), jnp.abs(im)
    big, small = jnp.maximum(a, b), jnp.minimum(a, b)
    ratio = small / jnp.where(big > 0, big, 1.0)  # tan of the angle to the nearer axis
    reduced = ratio > TAN_PI_8
    r = jnp.where(reduced, (ratio - 1.0) / (ratio + 1.0), ratio)  # atan(t) = π/4 + atan(r)
    t = jnp.where(reduced, np.pi / 4, 0.0) + r + r * (r * r) * _poly(r * r, ATAN_COEFFS)
    t = jnp.where(b > a, np.pi / 2 - t, t)
    t = jnp.where(re < 0, np.pi - t, t)
    return jnp.where(im < 0, -t, t)
