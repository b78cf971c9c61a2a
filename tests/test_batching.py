"""`vmap_minor` against `jax.vmap`: the same results, with the batch kept last inside.

Functions built from the primitives the simulator and the PARS iteration use (loops with a
per-example stopping test, gathers and scatters by static index, products with the batch on
either side, per-example dynamic slices, custom-JVP functions). Each is compared with
`jax.vmap` of the same function; the tolerance is float32 rounding (XLA may order a fused
sum differently in the two layouts). Derivatives through `vmap_minor` are `jax.vmap`'s, with
the custom rules inside honoured; the primitive table is checked against the installed JAX."""
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrid import batching
from jaxgrid.batching import batch_last, batch_major, fallbacks, vmap_minor
from jaxgrid.vecmath import sincos

RNG = np.random.default_rng(0)
X = RNG.normal(size=(7, 6)).astype(np.float32)
W = RNG.normal(size=(3, 3)).astype(np.float32)
M = RNG.normal(size=(5, 6)).astype(np.float32)
PICK = np.array([1, 4])


def program(x, w, i):
    """Loops, a cond, gathers, a scatter, products and a dynamic slice, for one example:
    x (6,), w (3, 3), i () int."""
    def body(c):
        k, y = c
        return k + 1, jnp.tanh(w @ y) + x[PICK].sum()

    # a while loop whose stopping test depends on the example
    k, y = jax.lax.while_loop(lambda c: (c[0] < 5) & (c[1].sum() < 3.0 + x[0]), body,
                              (0, x[:3]))
    # a scan whose first carry is batched only through the second, batched through xs
    (total, _), ys = jax.lax.scan(lambda c, z: ((c[0] + c[1], z), c[0]), (1.0, 0.0),
                                  x)
    flipped = jax.lax.cond(x[0] > 0, lambda: y * 2, lambda: -y)
    switched = jax.lax.switch(i % 3, [lambda: y, lambda: y + 1, lambda: y * y])
    s, c = sincos(x)
    window = jax.lax.dynamic_slice(jnp.asarray(M), (i, 2), (2, 3))
    column = jnp.asarray(M)[:, i]
    paired = jnp.stack([total, k.astype(total.dtype)])
    return {"joined": jnp.concatenate([y, flipped, switched, paired]),
            "scan": ys, "scatter": x.at[PICK].add(y[:2]), "inner": jnp.dot(x, x),
            "lhs": x[:3] @ w, "outer": jnp.outer(x[:2], y), "trig": s * c,
            "window": window, "column": jnp.cumsum(column), "tile": jnp.tile(y[:2], 2),
            "compare": (x[:3, None] < x[None, 3:]).sum(0), "argmax": jnp.argmax(x),
            "padded": jnp.pad(y, (1, 2)), "moved": jnp.transpose(jnp.reshape(x, (2, 3)))}


def assert_close(a, b):
    for key in a:
        np.testing.assert_allclose(np.asarray(a[key]), np.asarray(b[key]), rtol=1e-6,
                                   atol=1e-6, err_msg=key)


@pytest.mark.parametrize("w_batched", [False, True])
def test_vmap_minor_equals_vmap(w_batched):
    weights = np.stack([W * (1 + 0.1 * j) for j in range(7)]) if w_batched else W
    index = np.arange(7) % 4
    axes = (0, 0 if w_batched else None, 0)
    assert_close(jax.jit(vmap_minor(program, in_axes=axes))(X, weights, index),
                 jax.jit(jax.vmap(program, in_axes=axes))(X, weights, index))
    assert fallbacks(program, X, weights, index, in_axes=axes) == {}, \
        "a primitive here fell back to jax.vmap"


def test_nested_vmap_minor_equals_nested_vmap():
    weights = np.stack([W * (1 + 0.1 * j) for j in range(4)])
    index = np.arange(7) % 4

    def nested(vmap):
        return jax.jit(lambda xs, ws: vmap(lambda w: vmap(lambda x, i: program(x, w, i))(
            xs, index))(ws))

    assert_close(nested(vmap_minor)(X, weights), nested(jax.vmap)(X, weights))


def test_batch_last_keeps_the_batch_last():
    out = jax.jit(batch_last(program, in_axes=(-1, None, -1)))(X.T, W, np.arange(7) % 4)
    ref = jax.vmap(program, in_axes=(0, None, 0))(X, W, np.arange(7) % 4)
    for key in ref:
        np.testing.assert_allclose(np.moveaxis(np.asarray(out[key]), -1, 0),
                                   np.asarray(ref[key]), rtol=1e-6, atol=1e-6, err_msg=key)


def test_an_unknown_primitive_falls_back_to_vmap():
    """A primitive without a rule (here `sort`) still gives vmap's result."""
    def f(x):
        return jnp.sort(x) * 2

    np.testing.assert_array_equal(np.asarray(jax.jit(vmap_minor(f))(X)),
                                  np.asarray(jax.vmap(f)(X)))
    assert fallbacks(f, X) == {"sort": 1}


def test_mismatched_batch_sizes_are_named():
    with pytest.raises(ValueError, match=r"one batch size, got \[5, 7\]"):
        vmap_minor(lambda a, b: a + b)(X, X[:, :5].T)
    with pytest.raises(ValueError, match="in_axes has 1 and first 2 entries for 2 arguments"):
        vmap_minor(lambda a, b: a + b, in_axes=(0,))(X, X)
    with pytest.raises(ValueError, match=r"in_axes = \(1, 0\): each entry must be 0"):
        vmap_minor(lambda a, b: a + b, in_axes=(1, 0))(X, X)


def test_batch_major_functions_read_first_arguments_in_place():
    """Per-example matrices marked `first` reach a `batch_major` function untransposed: the
    results equal jax.vmap's and the compiled loop transposes no matrix."""
    mats = RNG.normal(size=(8, 5, 5)).astype(np.float32) * 0.3

    def run(w, x):
        apply = batch_major(lambda w, x: jnp.tanh(w @ x))
        return jax.lax.fori_loop(0, 4, lambda _, x: apply(w, x) + x.sum(), x)

    x = X[:, :5][np.arange(8) % 7]
    minor = jax.jit(vmap_minor(run, first=(True, False)))
    np.testing.assert_allclose(np.asarray(minor(mats, x)), np.asarray(jax.vmap(run)(mats, x)),
                               rtol=1e-6, atol=1e-6)
    hlo = minor.lower(mats, x).compile().as_text()
    assert not re.search(r"f32\[(8,5,5|5,5,8)\][^\n]* transpose\(", hlo)


# Derivatives through vmap_minor are jax.vmap's (its tangent rule is jax.jvp of jax.vmap of
# the per-example program), so the two differ only where XLA compiles the two programs' sums
# in a different order: float32 rounding of values of order 1 to 10.
GRAD_TOL = dict(rtol=1e-5, atol=1e-5)


@jax.custom_jvp
def straight_through_round(x):
    """round(x), differentiated as the identity (its primitives' derivative is 0)."""
    return jnp.round(x)


straight_through_round.defjvp(lambda primals, tangents: (straight_through_round(*primals),
                                                         tangents[0]))


@jax.custom_vjp
def clipped_gradient(x):
    """x, whose cotangent is clipped to [-0.1, 0.1] (its primitives' would pass whole)."""
    return x


clipped_gradient.defvjp(lambda x: (x, None), lambda _, g: (jnp.clip(g, -0.1, 0.1),))


def test_custom_rules_are_honoured():
    """The derivatives the rules give, not those of the primitives evaluated."""
    ones = jax.grad(lambda x: vmap_minor(straight_through_round)(x).sum())(X)
    np.testing.assert_array_equal(np.asarray(ones), np.ones_like(X))
    clipped = jax.grad(lambda x: (10 * vmap_minor(clipped_gradient)(x)).sum())(X)
    np.testing.assert_allclose(np.asarray(clipped), np.full_like(X, 0.1))


def custom_jvp_program(x, w):
    """sincos and a custom JVP rule inside a loop and a product: x (6,), w (3, 3)."""
    s, c = sincos(3.0 * x)
    y = jax.lax.fori_loop(0, 3, lambda _, y: jnp.tanh(w @ y) + s[:3], c[3:])
    return jnp.sum(y * straight_through_round(4.0 * x[:3])) + jnp.dot(s, c)


def custom_vjp_program(x, w):
    """A custom VJP rule between two products: x (6,), w (3, 3)."""
    return jnp.sum(jnp.sin(w @ clipped_gradient(5.0 * (w @ x[:3]))))


def batch_loss(vmap, program):
    """(x (7, 6), w (3, 3)) -> the sum of squares of `program` over the batch of x."""
    return lambda x, w: jnp.sum(vmap(program, in_axes=(0, None))(x, w) ** 2)


def assert_trees_close(a, b):
    for u, v in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_allclose(np.asarray(u), np.asarray(v), **GRAD_TOL)


@pytest.mark.parametrize("program", [custom_jvp_program, custom_vjp_program])
def test_grad_equals_vmap_grad(program):
    def grad(vmap):
        return jax.jit(jax.grad(batch_loss(vmap, program), argnums=(0, 1)))(X, W)

    assert_trees_close(grad(vmap_minor), grad(jax.vmap))


def test_jvp_equals_vmap_jvp():
    tangents = (RNG.normal(size=X.shape).astype(np.float32),
                RNG.normal(size=W.shape).astype(np.float32))

    def jvp(vmap):
        return jax.jit(lambda x, w: jax.jvp(batch_loss(vmap, custom_jvp_program), (x, w),
                                            tangents))(X, W)

    assert_trees_close(jvp(vmap_minor), jvp(jax.vmap))


def test_jvp_through_a_custom_vjp_is_refused_as_by_vmap():
    for vmap in (jax.vmap, vmap_minor):
        with pytest.raises(TypeError, match="can't apply forward-mode autodiff"):
            jax.jvp(batch_loss(vmap, custom_vjp_program), (X, W), (X, W))


def test_grad_through_nested_vmap_minor_equals_vmap():
    """The PARS shape: per-example weights batched outside (kept first), read by a
    `batch_major` function inside a batch over examples that closes over them."""
    weights = np.stack([W * (1 + 0.1 * j) for j in range(4)])

    def loss(vmap, **outer):
        def per_weight(w):
            apply = batch_major(lambda w, x: custom_jvp_program(x, w))
            return vmap(lambda x: apply(w, x))(X)

        return lambda ws: jnp.sum(vmap(per_weight, **outer)(ws) ** 2)

    assert_trees_close(jax.jit(jax.grad(loss(vmap_minor, first=True)))(weights),
                       jax.jit(jax.grad(loss(jax.vmap)))(weights))


def test_an_unknown_jax_or_primitive_is_refused(monkeypatch):
    rules, why = batching._rules_of_this_jax({"no_such_primitive": None})
    assert rules == {} and re.match(f"JAX {re.escape(jax.__version__)} has no primitive named "
                                    "no_such_primitive", why)
    monkeypatch.setattr(batching, "KNOWN_JAX", ((0, 1),))
    rules, why = batching._rules_of_this_jax(batching.RULES)
    assert rules == {} and re.match(f"JAX {re.escape(jax.__version__)} is not a release .* "
                                    r"checked against \(0\.1\.x\)", why)
    assert batching.REFUSED is None  # this JAX is known: the interpreter runs


def test_a_refused_table_runs_as_jax_vmap(monkeypatch):
    monkeypatch.setattr(batching, "REFUSED", "a JAX this table does not know")
    monkeypatch.setattr(batching, "batch_last", None)  # the interpreter is not entered
    assert_trees_close(vmap_minor(program, in_axes=(0, None, 0))(X, W, np.arange(7) % 4),
                       jax.vmap(program, in_axes=(0, None, 0))(X, W, np.arange(7) % 4))


def test_a_refused_table_runs_the_pars_iteration_as_before(monkeypatch):
    """The path a JAX outside `KNOWN_JAX` takes (pyproject.toml's range), through what a grid
    training batches with it: the PARS iteration of `jaxgrid.population` (vectors sharded
    over the devices, a `batch_major` policy network, loop episodes of different lengths,
    regrouped after a step) with the table refused runs as `jax.vmap` and ends at the fast
    path's θ to float32 rounding (the two layouts fuse sums in another order; 3 iterations of
    θ = O(1)), simulating the same steps."""
    from ars.iteration import default_mesh, make_iteration
    from ars.normalizer import initial_carry, normalized_policy
    from ars.pars import Pars, ParsConfig, init_state
    from ars.policies import Policy, PolicySpec
    from jaxgrid.population import evaluator
    from tests.test_ars import TARGETS, ShortfallEpisode

    policy = Policy(PolicySpec("lstm", 2, 2, (4,), -0.2, 0.0))
    config = ParsConfig(directions=4, top=2, step_size=0.2, noise=0.3, tasks_per_iteration=2,
                        compact_after=1, compact_chunks=3, seed=3)

    def train():
        mesh = default_mesh()
        evaluate = evaluator(ShortfallEpisode(), normalized_policy(policy, batch_major),
                             initial_carry(policy), mesh, config.task_batch,
                             config.compact_after, config.compact_chunks)
        iteration = make_iteration(Pars(config), evaluate, config.tasks_per_iteration,
                                   mesh=mesh)
        state, steps = init_state(policy, config), []
        for _ in range(3):
            state, metrics = iteration(state, TARGETS, 1.0)
            steps.append(int(metrics["env_steps"]))
        return np.asarray(state.theta), steps

    fast, fast_steps = train()
    monkeypatch.setattr(batching, "REFUSED", "a JAX this table does not know")
    monkeypatch.setattr(batching, "batch_last", None)  # the interpreter is not entered
    plain, plain_steps = train()
    np.testing.assert_allclose(plain, fast, rtol=1e-5, atol=1e-6)
    assert plain_steps == fast_steps
