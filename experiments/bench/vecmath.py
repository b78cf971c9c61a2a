"""Cost per element of the step's elementary functions: XLA's own against `jaxgrid.vecmath`.

    python -m experiments.bench.vecmath [--elements 14400] [--out benchmarks/cpu/vecmath.json]

Each function runs 200 times in a compiled loop over a float32 (complex64 for the angle)
array of `--elements` values, its output fed back into its input; the best of 5 calls gives
nanoseconds per element, beside a multiply, complex arithmetic and `jnp.exp`, which XLA
vectorises.
"""
from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np

from experiments.bench.timing import timed, write_report
from jaxgrid import vecmath

LOOPS = 200
EXPONENT = 2.7  # an ACMTBLU1-like running-curve exponent

# name: (function of a float32 array x in about [0.5, 1.5], returning an array like x)
FUNCTIONS = {
    "multiply": lambda x: x * 1.0001,
    "complex multiply": lambda x: jnp.real((x + 0.5j) * (0.9 + 0.1j)) + 0.05,
    "complex divide": lambda x: jnp.real((x + 0.5j) / (1.1 + 0.1j * x)) + 0.05,
    "jnp.exp": lambda x: 0.5 + jnp.exp(-x),
    "jnp.sin + jnp.cos": lambda x: 1.0 + 0.1 * (jnp.sin(x) + jnp.cos(x)),
    "vecmath.sincos": lambda x: 1.0 + 0.1 * sum(vecmath.sincos(x)),
    "jnp.power": lambda x: 0.5 + 0.5 * x ** EXPONENT,
    "vecmath.power": lambda x: 0.5 + 0.5 * vecmath.power(x, EXPONENT),
    "jnp.angle": lambda x: 1.0 + 0.1 * jnp.angle(x - 1.0 + 0.5j),
    "vecmath.angle": lambda x: 1.0 + 0.1 * vecmath.angle(x - 1.0 + 0.5j),
}


def ns_per_element(fn, n: int) -> float:
    """Best of 5 warm calls of LOOPS applications of fn to n elements, ns per element."""
    x0 = jnp.asarray(np.random.default_rng(0).uniform(0.5, 1.5, n), jnp.float32)
    looped = jax.jit(lambda x: jax.lax.fori_loop(0, LOOPS, lambda _, y: fn(y), x))
    timed(lambda: looped(x0))
    return 1e9 * min(timed(lambda: looped(x0))[1] for _ in range(5)) / (LOOPS * n)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--elements", type=int, default=14_400,
                        help="array size (default: 144 rollouts × 100 units)")
    parser.add_argument("--out", default="benchmarks/cpu/vecmath.json")
    args = parser.parse_args(argv)
    timings = {name: round(ns_per_element(fn, args.elements), 3)
               for name, fn in FUNCTIONS.items()}
    for name, ns in timings.items():
        print(f"{name:20s} {ns:7.3f} ns per element")
    write_report(args.out, elements=args.elements, loops=LOOPS, ns_per_element=timings)


if __name__ == "__main__":
    main()
