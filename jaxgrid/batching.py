"""`vmap_minor`: `jax.vmap` with the batch as the minor (last) axis of every array inside.

Why: `jax.vmap` puts the batch axis first. XLA:CPU then lays a device group's arrays out as
(batch, slot), while the network product and XLA's gathers produce (slot, batch); the fusions
between them read transposed and compile to scalar loops over a handful of slots
(`experiments/bench/profile_step.py`; docs/performance.md). Interpreting the per-rollout
program with the batch kept last makes every array (slot, ..., batch): one layout, loops over the
batch that vectorise, no transposes.

How: the function is traced once per call for one example (`jax.make_jaxpr`) and its jaxpr
evaluated with each value either unbatched or batched along a trailing axis of size B. Each
primitive has a rule keeping the batch last (elementwise ops broadcast their unbatched
operands, gathers and scatters take the batch as one more window dimension, loops carry it).
The primitives handled are declared in one table, `RULES`, checked at import against the
installed JAX: on a JAX release not in `KNOWN_JAX` (the releases of pyproject.toml's jax
range, which the tests run on), or one lacking a primitive of the table, the interpreter is
refused with a `BatchingWarning` naming both, and `vmap_minor` is plain `jax.vmap` (correct:
the simulator, the environment and the PARS iteration give `jax.vmap`'s results, tested in
tests/test_batching.py by refusing the table on this JAX; slower on CPU, by the factors
docs/performance.md measures, "The fast path refused"). `refuse` does the same on a known
JAX, to measure it (`experiments.bench.train --plain-vmap`). A primitive without a rule
falls back to `jax.vmap` of that primitive alone, moving the batch to the front and back
(correct, only slower; `fallbacks` lists them for a given call).

Per-example matrices are the exception: XLA's batched product wants their batch first. A
function wrapped in `batch_major` (the policy) is a `jax.jit` whose body starts by passing its
arguments through a marker primitive (an identity that lowers to nothing); a call holding it
is batched with `jax.vmap` where it is met, and arguments passed with `first` (the perturbed
θ) stay batch-first until something other than such a call reads them, so loop-invariant
weights are never transposed.

Differentiation: the batch-last evaluation is a `jax.custom_jvp` whose tangent rule is
`jax.jvp` of `jax.vmap` of the per-example program, so the primitives the interpreter
evaluates are never differentiated: custom rules inside (`jax.custom_jvp`, e.g.
`vecmath.sincos`'s; `jax.custom_vjp`) are honoured, reverse mode transposes that rule, and
values and derivatives under differentiation are `jax.vmap`'s (with its layout: the speed-up
is the forward evaluation's). As under `jax.vmap`, JAX refuses `jax.jvp` through a
`custom_vjp` function. Forward results equal `jax.vmap`'s up to float rounding (XLA may
fuse in a different order; tested).

On a GPU the layout question differs: XLA:GPU assigns layouts itself and emits transposes as
tiled kernels, and its step is launch-bound (docs/performance.md), so the CPU's transposed
fusions may cost nothing there (the GPU figures on record ran with the table refused, on
JAX 0.11.2). Dropping `vmap_minor` for plain `jax.vmap` on a GPU would take: timing the PARS
iteration (`experiments.bench.train`, 39- and 300-bus at the studies' N, with and without
`--plain-vmap`) on one GPU and a JAX release of `KNOWN_JAX`;
if `jax.vmap` is as fast, choosing by backend in this module alone (`jax.default_backend()`
not "cpu": `vmap_minor` returns `jax.vmap(fun, in_axes, out_axes)`, `first` is ignored and
`batch_major` is a plain `jax.jit`, since `jax.vmap` keeps every batch first); and keeping the
bitwise θ reference per backend (GPU results already differ from the CPU's by rounding).
Callers need no change: `vmap_minor`'s contract is `jax.vmap`'s.
"""
from __future__ import annotations

import warnings
from collections import Counter
from collections.abc import Callable, Sequence
from contextvars import ContextVar

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.extend import core
from jax.extend.core import primitives
from jax.interpreters import ad, mlir
from jax.interpreters import batching as jax_batching

KNOWN_JAX = ((0, 10),)  # JAX releases (major, minor) `RULES` was checked against (the tests;
# pyproject.toml's jax range: 0.10 is the newest release the project's package index serves)

FIRST = "first"  # the flag of a value kept batch-first (`vmap_minor`'s `first`)

# while `fallbacks` traces: {primitive name: times evaluated by the fallback}
_FALLBACK_COUNTS: ContextVar[Counter | None] = ContextVar("vmap_minor_fallbacks",
                                                          default=None)
# while `batch_last` traces: {(jaxpr, input flags): output flags} of `out_flags`, so that a
# loop body's flags are found once per trace, not again at each fixpoint round of every loop
# around it (nested loops made that exponential in their depth)
_OUT_FLAGS_MEMO: ContextVar[dict | None] = ContextVar("vmap_minor_out_flags", default=None)


def vmap_minor(fun: Callable, in_axes: int | None | Sequence = 0, out_axes: int = 0,
               first: bool | Sequence[bool] = False) -> Callable:
    """Like `jax.vmap(fun, in_axes, out_axes)` (in_axes: 0 or None per positional argument,
    or one for all), evaluated with the batch as every array's last axis inside: the batched
    arguments' leading axis is moved last on entry, and the outputs' last axis to
    `out_axes`. Arguments marked in `first` (per positional argument, or one for all) stay
    batch-first for the `batch_major` functions that read them (e.g. per-example policy
    weights), and are moved where anything else reads them. Plain `jax.vmap` when this JAX
    is not one the primitive table was checked against (`REFUSED`)."""
    if REFUSED:
        return jax.vmap(fun, in_axes, out_axes)
    inner = batch_last(fun, in_axes, first)

    def batched(*args):
        flat, tree = jax.tree.flatten(args)
        flags = _flags_of_args(args, in_axes, first)
        minor = [jnp.moveaxis(x, 0, -1) if b is True else x for x, b in zip(flat, flags)]
        out = inner(*jax.tree.unflatten(tree, minor))
        return jax.tree.map(lambda x: jnp.moveaxis(x, -1, out_axes), out)

    return batched


def batch_last(fun: Callable, in_axes: int | None | Sequence = -1,
               first: bool | Sequence[bool] = False) -> Callable:
    """`fun` (written for one example) over a batch held as the LAST axis of every batched
    argument (in_axes: -1 or None per positional argument, or one for all; the first axis
    for arguments marked in `first`); every output gets the batch as its last axis.
    `vmap_minor` without the moves on entry and exit."""

    def batched(*args):
        flat, tree = jax.tree.flatten(args)
        flags = _flags_of_args(args, in_axes, first)
        sizes = {np.shape(x)[0 if b is FIRST else -1] for x, b in zip(flat, flags) if b}
        if len(sizes) != 1:
            raise ValueError(f"vmap_minor: the batched arguments need one batch size, got "
                             f"{sorted(sizes)}")
        size = sizes.pop()
        example = [jax.ShapeDtypeStruct(np.shape(x)[1:] if b is FIRST else np.shape(x)[:-1],
                                        jnp.result_type(x)) if b else x
                   for x, b in zip(flat, flags)]
        closed, out_shape = jax.make_jaxpr(
            lambda *leaves: fun(*jax.tree.unflatten(tree, leaves)), return_shape=True)(*example)
        token = _OUT_FLAGS_MEMO.set({}) if _OUT_FLAGS_MEMO.get() is None else None
        try:
            outs = _differentiable(closed.jaxpr, flags, size)(closed.consts, flat)
        finally:
            if token is not None:
                _OUT_FLAGS_MEMO.reset(token)
        return jax.tree.unflatten(jax.tree.structure(out_shape), outs)

    return batched


def fallbacks(fun: Callable, *args, in_axes: int | None | Sequence = 0,
              first: bool | Sequence[bool] = False) -> dict[str, int]:
    """{primitive name: times met} for the primitives of `vmap_minor(fun, in_axes,
    first=first)(*args)` that no rule keeps batch-last (each evaluated as `jax.vmap` of that
    primitive alone: correct, only slower). Traced, not run; nested `vmap_minor`s count."""
    counts = Counter()
    token = _FALLBACK_COUNTS.set(counts)
    try:
        jax.make_jaxpr(vmap_minor(fun, in_axes, first=first))(*args)
    finally:
        _FALLBACK_COUNTS.reset(token)
    return dict(counts)


def _differentiable(jaxpr, flags, size: int) -> Callable:
    """(consts, args) -> `jaxpr`'s outputs, each with a trailing batch axis of `size`, for
    args flagged `flags`: the batch-last evaluation, differentiated as `jax.vmap` of the
    per-example program (see the module docstring), never through the primitives the
    evaluation binds."""
    axes = [0 if f is FIRST else -1 if f else None for f in flags]

    @jax.custom_jvp
    def run(consts, args):
        return [_batched(x, b, size) for x, b in evaluate(jaxpr, consts, args, flags, size)]

    @run.defjvp
    def run_jvp(primals, tangents):
        def one(consts, args):
            return core.jaxpr_as_fun(core.ClosedJaxpr(jaxpr, consts))(*args)

        return jax.jvp(jax.vmap(one, in_axes=(None, axes), out_axes=-1), primals, tangents)

    return run


def _flags_of_args(args, in_axes, first) -> list:
    """Per leaf of `args`: False (not batched), True (batched) or FIRST (kept batch-first)."""
    axes = in_axes if isinstance(in_axes, (list, tuple)) else (in_axes,) * len(args)
    firsts = first if isinstance(first, (list, tuple)) else (first,) * len(args)
    if len(axes) != len(args) or len(firsts) != len(args):
        raise ValueError(f"vmap_minor: in_axes has {len(axes)} and first {len(firsts)} "
                         f"entries for {len(args)} arguments")
    if any(a not in (0, -1, None) for a in axes):
        raise ValueError(f"vmap_minor: in_axes = {in_axes!r}: each entry must be 0 (-1 for "
                         "batch_last) or None")
    return jax.tree.leaves(tuple(
        jax.tree.map(lambda _, a=a, f=f: (FIRST if f else True) if a is not None else False,
                     arg) for arg, a, f in zip(args, axes, firsts)))


def evaluate(jaxpr, consts, args, flags, size: int):
    """Values of `jaxpr`'s outputs as (value, flag) pairs for inputs flagged `flags`: False
    (unbatched), True (the batch of size `size` is the last axis) or FIRST (the first)."""
    env = {}

    def read(v):
        return (v.val, False) if isinstance(v, core.Literal) else env[v]

    for var, val in zip(jaxpr.constvars, consts):
        env[var] = (val, False)
    for var, val, flag in zip(jaxpr.invars, args, flags):
        env[var] = (val, flag)
    for eqn in jaxpr.eqns:
        vals, batched = zip(*map(read, eqn.invars)) if eqn.invars else ((), ())
        if not any(batched):
            outs = _pairs(eqn, eqn.primitive.bind(
                *vals, **eqn.primitive.get_bind_params(eqn.params)), False)
        else:
            if FIRST in batched and _RULE_OF.get(eqn.primitive) not in _PASS_FIRST:
                vals, batched = zip(*map(_to_last, vals, batched))
            outs = _apply(eqn, list(vals), list(batched), size)
        for var, pair in zip(eqn.outvars, outs):
            env[var] = pair
    return [read(v) for v in jaxpr.outvars]


def _to_last(x, flag):
    """A `FIRST` value moved to the batch-last layout."""
    return (jnp.moveaxis(x, 0, -1), True) if flag is FIRST else (x, flag)


def _batched(x, flag, size: int):
    """x with a trailing batch axis, broadcast if it has none."""
    if flag is FIRST:
        return jnp.moveaxis(x, 0, -1)
    if flag:
        return x
    x = jnp.asarray(x)
    return lax.broadcast_in_dim(x, x.shape + (size,), tuple(range(x.ndim)))


def _apply(eqn, vals, batched, size):
    rule = _RULE_OF.get(eqn.primitive, _fallback)
    return rule(eqn, vals, batched, size, **eqn.params)


def _fallback(eqn, vals, batched, size, **_):
    """`jax.vmap` of the one primitive, with the batch moved to the front and back."""
    counts = _FALLBACK_COUNTS.get()
    if counts is not None:
        counts[eqn.primitive.name] += 1
    params = eqn.primitive.get_bind_params(eqn.params)
    out = _batch_first(lambda *a: eqn.primitive.bind(*a, **params), vals, batched)
    return _pairs(eqn, out)


def _batch_first(fun, vals, batched):
    """`jax.vmap(fun)` over the batched values, their batch moved to the front (FIRST ones
    are there already) and the outputs' back to the end."""
    front = [jnp.moveaxis(v, -1, 0) if b is True else v for v, b in zip(vals, batched)]
    out = jax.vmap(fun, in_axes=[0 if b else None for b in batched])(*front)
    return jax.tree.map(lambda o: jnp.moveaxis(o, 0, -1), out)


def _pairs(eqn, out, flag=True):
    """The (value, flag) pairs of an equation's output(s)."""
    return [(o, flag) for o in (out if eqn.primitive.multiple_results else [out])]


def _elementwise(eqn, vals, batched, size, **params):
    """Every operand broadcast to the output's per-example shape (numpy rules: lax's binary
    ops broadcast size-1 axes) with the batch last."""
    shapes = [np.shape(v)[:np.ndim(v) - b] for v, b in zip(vals, batched)]
    shape = tuple(np.broadcast_shapes(*shapes))
    full = shape + (size,)

    def conform(v, b, own):
        if b and own == shape:
            return v
        dims = tuple(range(len(shape) - len(own), len(shape)))
        return lax.broadcast_in_dim(v, full, dims + ((len(shape),) if b else ()))

    return _pairs(eqn, eqn.primitive.bind(
        *[conform(v, b, s) for v, b, s in zip(vals, batched, shapes)], **params))


def _leading_axes(eqn, vals, batched, size, **params):
    """A one-operand primitive whose parameters name the per-example axes it acts on: the
    trailing batch axis rides along."""
    return _pairs(eqn, eqn.primitive.bind(*vals, **params))


def _broadcast_in_dim(eqn, vals, batched, size, shape, broadcast_dimensions, sharding):
    operand, *dynamic = vals
    if any(batched[1:]):
        return _fallback(eqn, vals, batched, size)
    return [(lax.broadcast_in_dim(operand, tuple(shape) + (size,),
                                  tuple(broadcast_dimensions) + (len(shape),)), True)]


def _reshape(eqn, vals, batched, size, new_sizes, dimensions, sharding):
    if dimensions is not None or len(vals) > 1:
        return _fallback(eqn, vals, batched, size)
    return [(jnp.reshape(vals[0], tuple(new_sizes) + (size,)), True)]


def _transpose(eqn, vals, batched, size, permutation):
    return [(lax.transpose(vals[0], tuple(permutation) + (len(permutation),)), True)]


def _slice(eqn, vals, batched, size, start_indices, limit_indices, strides):
    strides = None if strides is None else tuple(strides) + (1,)
    return [(lax.slice(vals[0], tuple(start_indices) + (0,), tuple(limit_indices) + (size,),
                       strides), True)]


def _dynamic_slice(eqn, vals, batched, size, slice_sizes):
    operand, *starts = vals
    if any(batched[1:]) and not batched[0]:
        # per-example starts into a shared operand: a gather whose batch axis is last
        rank = np.ndim(operand)
        index = jnp.stack([_batched(i, b, size) for i, b in zip(starts, batched[1:])], axis=1)
        dn = lax.GatherDimensionNumbers(offset_dims=tuple(range(rank)), collapsed_slice_dims=(),
                                        start_index_map=tuple(range(rank)))
        return [(lax.gather(operand, index, dn, tuple(slice_sizes),
                            mode=lax.GatherScatterMode.CLIP), True)]
    if any(batched[1:]):
        return _fallback(eqn, vals, batched, size)
    zero = jnp.zeros((), jnp.result_type(starts[0]) if starts else jnp.int32)
    return [(lax.dynamic_slice(operand, list(starts) + [zero], tuple(slice_sizes) + (size,)),
             True)]


def _dynamic_update_slice(eqn, vals, batched, size):
    operand, update, *starts = vals
    if any(batched[2:]):
        return _fallback(eqn, vals, batched, size)
    zero = jnp.zeros((), jnp.result_type(starts[0]) if starts else jnp.int32)
    return [(lax.dynamic_update_slice(_batched(operand, batched[0], size),
                                      _batched(update, batched[1], size),
                                      list(starts) + [zero]), True)]


def _concatenate(eqn, vals, batched, size, dimension):
    return [(lax.concatenate([_batched(v, b, size) for v, b in zip(vals, batched)],
                             dimension), True)]


def _pad(eqn, vals, batched, size, padding_config):
    operand, value = vals
    if batched[1]:
        return _fallback(eqn, vals, batched, size)
    return [(lax.pad(operand, value, tuple(padding_config) + ((0, 0, 0),)), True)]


def _gather(eqn, vals, batched, size, dimension_numbers, slice_sizes, **params):
    operand, indices = vals
    if batched[1]:
        return _fallback(eqn, vals, batched, size)
    dn = dimension_numbers
    out_rank = len(eqn.outvars[0].aval.shape)
    dn = dn._replace(offset_dims=tuple(dn.offset_dims) + (out_rank,))
    return [(lax.gather_p.bind(operand, indices, dimension_numbers=dn,
                               slice_sizes=tuple(slice_sizes) + (size,), **params), True)]


def _scatter(eqn, vals, batched, size, dimension_numbers, **params):
    operand, indices, updates = vals
    if batched[1]:
        return _fallback(eqn, vals, batched, size)
    dn = dimension_numbers
    updates_rank = len(eqn.invars[2].aval.shape)
    dn = dn._replace(update_window_dims=tuple(dn.update_window_dims) + (updates_rank,))
    return [(eqn.primitive.bind(_batched(operand, batched[0], size), indices,
                                _batched(updates, batched[2], size), dimension_numbers=dn,
                                **params), True)]


def _dot_general(eqn, vals, batched, size, dimension_numbers, **params):
    (lc, rc), (lb, rb) = dimension_numbers
    lhs, rhs = vals
    out_ndim = len(eqn.outvars[0].aval.shape)
    if batched[0] and batched[1]:
        nl, nr = np.ndim(lhs) - 1, np.ndim(rhs) - 1
        if not lb and len(lc) == nl and len(rc) == nr:  # an inner product: no transposes
            aligned = lax.transpose(rhs, tuple(rc[list(lc).index(i)] for i in range(nl)) + (nr,))
            out = jnp.sum(lhs * aligned, axis=tuple(range(nl)))
            dtype = params.get("preferred_element_type")
            return [(out if dtype is None else out.astype(dtype), True)]
        out = lax.dot_general_p.bind(lhs, rhs, dimension_numbers=(
            (lc, rc), (tuple(lb) + (nl,), tuple(rb) + (nr,))), **params)
        return [(jnp.moveaxis(out, len(lb), -1), True)]
    out = lax.dot_general_p.bind(lhs, rhs, dimension_numbers=dimension_numbers, **params)
    if batched[1]:  # the batch is rhs's last free axis: the output's last
        return [(out, True)]
    # lhs's last free axis: after lhs's free axes, before rhs's
    rhs_free = np.ndim(rhs) - len(rc) - len(rb)
    return [(jnp.moveaxis(out, out_ndim - rhs_free, -1), True)]


def batch_major(fun: Callable) -> Callable:
    """`fun`, to be batched with the batch FIRST (`jax.vmap`) where `vmap_minor` meets it.

    For per-example matrices (a policy's weights, one set per perturbed θ): XLA's batched
    product wants the batch as their leading axis, so batch-last weights are transposed at
    every call; moved to the front at the call instead, a loop-invariant θ is moved once.
    A `jax.jit` whose body starts with `_BATCH_MAJOR` (an identity) on its arguments."""
    def marked(*args):
        leaves, tree = jax.tree.flatten(args)
        return fun(*jax.tree.unflatten(tree, _BATCH_MAJOR.bind(*leaves)))

    return jax.jit(marked)


# The mark of a `batch_major` call's body: an identity on its operands, lowered to nothing.
_BATCH_MAJOR = core.Primitive("batch_major")
_BATCH_MAJOR.multiple_results = True
_BATCH_MAJOR.def_impl(lambda *xs: xs)
_BATCH_MAJOR.def_abstract_eval(lambda *avals: avals)
mlir.register_lowering(_BATCH_MAJOR, lambda ctx, *xs: xs)
jax_batching.primitive_batchers[_BATCH_MAJOR] = lambda xs, dims: (_BATCH_MAJOR.bind(*xs), dims)
ad.primitive_jvps[_BATCH_MAJOR] = lambda xs, dxs: (_BATCH_MAJOR.bind(*xs), list(dxs))


def _call(eqn, vals, batched, size, **params):
    """jit, closed_call, remat, custom_jvp_call, custom_vjp_call: evaluate the body
    (`batch_major` calls: `jax.vmap` of it, the batch moved to the front and back)."""
    closed = _body(params)
    if any(e.primitive is _BATCH_MAJOR for e in closed.jaxpr.eqns):
        return [(o, True) for o in _batch_first(jax.jit(core.jaxpr_as_fun(closed)),
                                                 vals, batched)]
    return evaluate(closed.jaxpr, closed.consts, vals, batched, size)


def out_flags(jaxpr, flags) -> list:
    """Which outputs of `jaxpr` are batched for inputs batched as `flags`: any batched input
    batches every output, except through calls and loops, which are followed inside.
    Remembered for the trace of one `batch_last` call (`_OUT_FLAGS_MEMO`)."""
    memo = _OUT_FLAGS_MEMO.get()
    key = (jaxpr, tuple(map(bool, flags)))
    if memo is None:
        return _out_flags(jaxpr, key[1])
    if key not in memo:
        memo[key] = _out_flags(jaxpr, key[1])
    return list(memo[key])


def _out_flags(jaxpr, flags: tuple[bool, ...]) -> list:
    env = dict(zip(jaxpr.invars, flags))
    read = lambda v: False if isinstance(v, core.Literal) else env.get(v, False)  # noqa: E731
    for eqn in jaxpr.eqns:
        ins = [read(v) for v in eqn.invars]
        rule = _RULE_OF.get(eqn.primitive)
        if not any(ins):
            outs = [False] * len(eqn.outvars)
        elif rule is _call:
            outs = out_flags(_body(eqn.params).jaxpr, ins)
        elif rule is _while:
            outs, _ = _while_flags(eqn.params, ins)
        elif rule is _scan:
            carry, ys = _scan_flags(eqn.params, ins)
            outs = carry + ys
        elif rule is _cond:
            outs = _cond_flags(eqn.params, ins)
        else:
            outs = [True] * len(eqn.outvars)
        env.update(zip(eqn.outvars, outs))
    return [bool(read(v)) for v in jaxpr.outvars]


def _body(params):
    closed = next(params[k] for k in ("jaxpr", "call_jaxpr") if k in params)
    return closed if hasattr(closed, "consts") else core.ClosedJaxpr(closed, ())


def _fixpoint(body, before, carry, after=()):
    """Carry flags of a loop whose body takes (before, carry, after): a carry is batched once
    the body batches it."""
    carry = [bool(c) for c in carry]
    while True:
        outs = out_flags(body.jaxpr, list(before) + carry + list(after))
        new = [c or o for c, o in zip(carry, outs)]
        if new == carry:
            return carry
        carry = new


def _while_flags(params, flags):
    """(carry flags, whether the stopping test is batched); a batched test batches every
    carry (each example keeps its own once its loop has ended)."""
    nc, nb = params["cond_nconsts"], params["body_nconsts"]
    cond_c, body_c, init = flags[:nc], flags[nc:nc + nb], flags[nc + nb:]
    carry = _fixpoint(params["body_jaxpr"], body_c, init)
    pred = out_flags(params["cond_jaxpr"].jaxpr, list(cond_c) + carry)[0]
    return ([True] * len(carry) if pred else carry), pred


def _scan_flags(params, flags):
    """(carry flags, stacked-output flags) of a scan."""
    nc, nk = params["num_consts"], params["num_carry"]
    consts, init, xs = flags[:nc], flags[nc:nc + nk], flags[nc + nk:]
    carry = _fixpoint(params["jaxpr"], consts, init, xs)
    return carry, out_flags(params["jaxpr"].jaxpr, list(consts) + carry + list(xs))[nk:]


def _cond_flags(params, flags):
    index, ops = flags[0], flags[1:]
    outs = [any(f) for f in zip(*(out_flags(b.jaxpr, ops) for b in params["branches"]))]
    return [bool(o or index) for o in outs]


def _evaluate_closed(closed, vals, flags, size, want):
    """Evaluate a closed jaxpr, then broadcast outputs to the `want` flags."""
    pairs = evaluate(closed.jaxpr, closed.consts, vals, flags, size)
    return [_batched(x, b, size) if w else x for (x, b), w in zip(pairs, want)]


def _while(eqn, vals, batched, size, cond_nconsts, cond_jaxpr, body_nconsts, body_jaxpr):
    carry_flags, pred_batched = _while_flags(eqn.params, batched)
    nc, nb = cond_nconsts, body_nconsts
    cond_c, body_c, init = vals[:nc], vals[nc:nc + nb], vals[nc + nb:]
    cond_f, body_f = batched[:nc], batched[nc:nc + nb]
    init = [_batched(v, b, size) if f else v
            for v, f, b in zip(init, carry_flags, batched[nc + nb:])]

    def predicate(carry):
        (p, _), = evaluate(cond_jaxpr.jaxpr, cond_jaxpr.consts, list(cond_c) + list(carry),
                           list(cond_f) + carry_flags, size)
        return p

    def cond_fun(carry):
        p = predicate(carry)
        return jnp.any(p) if pred_batched else p

    def body_fun(carry):
        new = _evaluate_closed(body_jaxpr, list(body_c) + list(carry),
                               list(body_f) + carry_flags, size, carry_flags)
        if pred_batched:  # examples whose loop has ended keep their carry
            live = predicate(carry)
            new = [jnp.where(jnp.reshape(live, (1,) * (jnp.ndim(n) - 1) + (size,)), n, c)
                   for n, c in zip(new, carry)]
        return new

    out = lax.while_loop(cond_fun, body_fun, list(init))
    return list(zip(out, carry_flags))


def _scan(eqn, vals, batched, size, reverse, length, jaxpr, num_consts, num_carry, unroll,
          **_):
    carry_flags, ys_flags = _scan_flags(eqn.params, batched)
    consts, init, xs = (vals[:num_consts], vals[num_consts:num_consts + num_carry],
                        vals[num_consts + num_carry:])
    c_f, x_f = batched[:num_consts], batched[num_consts + num_carry:]
    init = [_batched(v, b, size) if f else v
            for v, f, b in zip(init, carry_flags, batched[num_consts:num_consts + num_carry])]
    xs = [_batched(v, b, size) if b else v for v, b in zip(xs, x_f)]
    x_f = [bool(b) for b in x_f]

    def body(carry, x):
        outs = _evaluate_closed(jaxpr, list(consts) + list(carry) + list(x),
                                list(c_f) + carry_flags + list(x_f), size,
                                carry_flags + ys_flags)
        return outs[:num_carry], outs[num_carry:]

    carry, ys = lax.scan(body, list(init), list(xs), length=length, reverse=reverse,
                         unroll=unroll)
    return list(zip(carry, carry_flags)) + list(zip(ys, ys_flags))


def _cond(eqn, vals, batched, size, branches, **_):
    index, ops = vals[0], vals[1:]
    flags = _cond_flags(eqn.params, batched)
    run = [lambda *o, b=b: _evaluate_closed(b, list(o), batched[1:], size, flags)
           for b in branches]
    if not batched[0]:
        return list(zip(lax.switch(index, run, *ops), flags))
    results = [r(*ops) for r in run]  # a batched index: every branch, then a selection
    return [(lax.select_n(lax.broadcast_in_dim(index, jnp.shape(outs[0]),
                                               (jnp.ndim(outs[0]) - 1,)), *outs), True)
            for outs in zip(*results)]


# The primitives with a batch-last rule, by their names in the JAX releases of `KNOWN_JAX`.
RULES: dict[str, Callable] = {
    **dict.fromkeys("""
        abs acos acosh add and asin asinh atan atan2 atanh cbrt ceil clamp complex conj
        convert_element_type copy cos cosh digamma div eq erf erf_inv erfc exp exp2 expm1 floor
        ge gt imag integer_pow is_finite le lgamma log log1p logistic lt max min mul ne neg
        nextafter not optimization_barrier or population_count pow real reduce_precision rem
        round rsqrt select_n shift_left shift_right_arithmetic shift_right_logical sign sin
        sinh sqrt square stop_gradient sub tan tanh xor""".split(), _elementwise),
    **dict.fromkeys("""
        argmax argmin cumlogsumexp cummax cummin cumprod cumsum reduce_and reduce_max
        reduce_min reduce_or reduce_prod reduce_sum reduce_xor rev split squeeze""".split(),
                    _leading_axes),
    **dict.fromkeys("jit closed_call remat2 custom_jvp_call custom_vjp_call".split(), _call),
    "broadcast_in_dim": _broadcast_in_dim,
    "reshape": _reshape,
    "transpose": _transpose,
    "slice": _slice,
    "dynamic_slice": _dynamic_slice,
    "dynamic_update_slice": _dynamic_update_slice,
    "concatenate": _concatenate,
    "pad": _pad,
    "gather": _gather,
    "scatter": _scatter,
    "scatter-add": _scatter,
    "dot_general": _dot_general,
    "while": _while,
    "scan": _scan,
    "cond": _cond,
    "tile": lambda eqn, vals, batched, size, reps: [
        (eqn.primitive.bind(vals[0], reps=tuple(reps) + (1,)), True)],
    "stack": lambda eqn, vals, batched, size, axis: [
        (jnp.stack([_batched(v, b, size) for v, b in zip(vals, batched)], axis), True)],
}
_PASS_FIRST = (_call, _while, _scan, _cond)  # hand FIRST values on to their bodies


class BatchingWarning(UserWarning):
    """`vmap_minor` cannot trust its primitive table on this JAX and runs as `jax.vmap`."""


def _rules_of_this_jax(rules: dict) -> tuple[dict, str | None]:
    """(`rules` keyed on this JAX's primitive objects (`jax.extend.core.primitives`,
    `jax.lax`), None), or ({}, why) for a JAX release not in `KNOWN_JAX` or a name it lacks."""
    version = tuple(jax.__version_info__[:2])
    known = ", ".join(".".join(map(str, v)) for v in KNOWN_JAX)
    if version not in KNOWN_JAX:
        return {}, (f"JAX {jax.__version__} is not a release its primitive table was checked "
                    f"against ({known}.x): install one of those, or run "
                    "tests/test_batching.py on this one and add it to KNOWN_JAX")
    found = {p.name: p for module in (primitives, lax) for p in vars(module).values()
             if isinstance(p, core.Primitive)}
    missing = sorted(set(rules) - set(found))
    if missing:
        return {}, (f"JAX {jax.__version__} has no primitive named {', '.join(missing)}: "
                    "RULES must be revised for it")
    return {found[name]: rule for name, rule in rules.items()}, None


_RULE_OF, REFUSED = _rules_of_this_jax(RULES)  # REFUSED: why vmap_minor is jax.vmap, or None
if REFUSED:
    warnings.warn(f"jaxgrid.batching: {REFUSED}; vmap_minor runs as jax.vmap (correct, "
                  "slower on CPU)", BatchingWarning, stacklevel=2)


def refuse(reason: str) -> None:
    """From now on `vmap_minor` runs as `jax.vmap` (`batch_major` calls as they are), as on
    a JAX outside `KNOWN_JAX`: what that costs is measured with it (`experiments.bench.train
    --plain-vmap`). Functions already traced keep their batching."""
    global REFUSED
    REFUSED = reason
