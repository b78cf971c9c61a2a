"""Where one integration step's time goes, for a model and a batch of tasks
(`profile_model`): the compiled step's kernels (`kernels`) and the time of each of its
components; `experiments.bench.profile_step` (which says what each number is) and
`experiments.bench.scale` report them."""
from __future__ import annotations

import re
from collections import Counter

import jax
import jax.numpy as jnp
import numpy as np

from experiments.bench.timing import timed
from jaxgrid import network
from jaxgrid.batching import batch_last
from jaxgrid.dynamics import (clip_to_limits, derivatives, load_injection, solve_network,
                              update_loads)
from jaxgrid.simulate import Bounds, within_bounds
from jaxgrid.steppers import Solver, axpy, heun_step

NOT_KERNELS = {"parameter", "constant", "tuple", "get-tuple-element", "bitcast"}
STEPS_PER_CALL = 50


def kernels(compiled_text: str) -> dict:
    """Counts of the ENTRY computation's instructions by opcode, and of fusions by content."""
    computations = dict(re.findall(r"\n((?:ENTRY )?%?[\w.\-]+) [^\n]*\{\n(.*?)\n\}",
                                   "\n" + compiled_text, re.S))
    entry = next(body for name, body in computations.items() if name.startswith("ENTRY"))
    ops = Counter()
    content = Counter()
    for line in entry.splitlines():
        match = re.search(r"= \S+ (\w[\w\-]*)\(", line)
        if not match or match.group(1) in NOT_KERNELS:
            continue
        ops[match.group(1)] += 1
        called = re.search(r"calls=%?([\w.\-]+)", line)
        if match.group(1) == "fusion" and called:
            body = next((b for n, b in computations.items()
                         if n.lstrip("%") == called.group(1)), "")
            for kind, pattern in (("complex", r"\bc(64|128)\["), ("transpose", r" transpose\("),
                                  ("gather", r" gather\("), ("scatter", r" scatter\(")):
                content[kind] += bool(re.search(pattern, line + body))
    return {"total": sum(ops.values()), "by_opcode": dict(ops.most_common()),
            "fusions_with": dict(content),
            "scalar_math": dict(Counter(re.findall(r"= \S+ (sine|cosine|power|atan2)\(",
                                                   compiled_text)))}


def _best_us(fn, args, calls: int, rollout_steps: int) -> float:
    """µs per rollout-step: the best of `calls` warm calls of fn(*args)."""
    timed(lambda: fn(*args))
    return 1e6 * min(timed(lambda: fn(*args))[1] for _ in range(calls)) / rollout_steps


def profile_model(model, solver: Solver, tasks, calls: int) -> dict:
    """Kernels and µs per rollout-step of `model` stepped by `solver` (at its dt) on a batch
    of `tasks` (leading axis), during the fault (module docstring)."""
    dt, sweeps = solver.dt, solver.sweeps
    batch = int(tasks.fault_bus.shape[0])
    states = jax.tree.map(lambda a: np.broadcast_to(a, (batch,) + a.shape), model.initial)
    t_fault = np.float32(np.max(tasks.fault_start) + 0.5 * dt)

    def fault_of(model, task):
        return network.fault_view(model.network, task.fault_bus, task.fault_z)

    def euler(model, x, fault):
        dx, v, _ = derivatives(model, x, fault, 1.0, sweeps)
        return x.with_integrated(axpy(dt, dx, x.integrated()), v)

    def one_step(model, x, task):
        return heun_step(model, x, t_fault, solver, task, fault_of(model, task))[0]

    # each component fed back into the state, so a loop of them is not hoisted
    components = {
        "step": one_step,
        "solve": lambda model, x, task: x.replace(
            v=solve_network(model, x, fault_of(model, task), 1.0, sweeps)[0]),
        "load_currents": lambda model, x, task: x.replace(v=x.v.at[model.n_gen:].set(
            load_injection(model, x, x.v[model.n_gen:]))),
        "product": lambda model, x, task: x.replace(v=network.times(model.network.zr_ss, x.v)),
        "rhs": lambda model, x, task: euler(model, x, fault_of(model, task)),
        "loads": lambda model, x, task: update_loads(model, x, 0.999 * x.v, dt),
        "clip": lambda model, x, task: x.with_integrated(
            clip_to_limits(model, x.integrated()), x.v),
        "check": lambda model, x, task: x.replace(
            v=jnp.where(within_bounds(x, Bounds()), x.v, 0.0 * x.v))}

    def looped(component):
        def run(model, x, task):
            return jax.lax.fori_loop(0, STEPS_PER_CALL,
                                     lambda k, x: component(model, x, task), x)
        return jax.jit(batch_last(run, in_axes=(None, -1, -1)))

    # the batch as the simulator holds it (`jaxgrid.batching`): every array's last axis
    args = (model, *jax.tree.map(lambda a: np.moveaxis(a, 0, -1), (states, tasks)))
    step_text = jax.jit(batch_last(one_step, in_axes=(None, -1, -1))).lower(
        *args).compile().as_text()
    times = {f"{key}_us": _best_us(looped(f), args, calls, batch * STEPS_PER_CALL)
             for key, f in components.items()}
    times["devices_us"] = times["rhs_us"] - times["solve_us"]
    share = {"network (2 solutions)": 2 * times["solve_us"] / times["step_us"],
             "device models (2 evaluations)": 2 * times["devices_us"] / times["step_us"],
             "load models' discrete update": times["loads_us"] / times["step_us"],
             "limit clips (2)": 2 * times["clip_us"] / times["step_us"]}
    share["rest (state updates, events, copies)"] = 1 - sum(share.values())
    share["of which load injections"] = 2 * sweeps * times["load_currents_us"] / times["step_us"]
    share["of which impedance products"] = 2 * sweeps * times["product_us"] / times["step_us"]
    return {"batch": batch, "dt_s": dt, "n_slot": len(model.slot_bus),
            "sweeps": sweeps, "kernels_per_step": kernels(step_text),
            "us_per_rollout_step": {k: round(v, 3) for k, v in times.items()},
            "share_of_step": {k: round(v, 3) for k, v in share.items()}}
