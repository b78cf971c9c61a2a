"""Decision latency: the time a controller takes to turn one observation into one action.

    python -m experiments.bench.latency [--studies ieee39_fidvr ieee300_fidvr]
        [--batch 1024] [--calls 200] [--mpc "horizon=1,iterations=10"] [--mpc-batch 32]
        [--out benchmarks/cpu/latency.json]

For each study, the PARS policies (each kind on the observations the study stacks for it,
`Study.history`; widths of the paper's preset for the grid's size,
`experiments.train.paper_preset`) with their observation normaliser, or given trained
policies (`bench_study(..., policies=)`, as `experiments.reproduce`'s tab3), the UVLS
relays and the MPC (`baselines.mpc`, options --mpc): the median wall time of one jitted
decision for one
task (batch 1, result on the host), and the time per decision when a batch of tasks decides
at once (one vmapped call / batch; --mpc-batch for the MPC). The MPC decides from the state
0.3 s after the start of the study's first test fault, the policies from a constant
observation. The paper's Table III reports 0.72 s per PARS decision and 63.31 s per MPC
decision. Compile time is excluded; θ is random unless trained policies are given (the cost
does not depend on its values).
"""
from __future__ import annotations

import argparse
import statistics
import time

import jax
import jax.numpy as jnp

from ars.pars import initial_carry
from ars.policies import Policy, PolicySpec
from baselines.controllers import pars_apply
from baselines.mpc import mpc_controller, parse_options
from baselines.uvls import uvls_policy
from experiments.bench.timing import write_report
from experiments.train import paper_preset
from jaxgrid.env import PlanInputs
from jaxgrid.study import load_study


def _median_call(fn, args, calls: int) -> float:
    jax.block_until_ready(fn(*args))  # compile
    times = []
    for _ in range(calls):
        start = time.perf_counter()
        jax.device_get(fn(*args))
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _controllers(study):
    """[(label, env, policy_apply, params, carry)] of random-θ PARS policies of each kind."""
    out = []
    widths = tuple(int(h) for h in paper_preset(study)["hidden"].split(","))
    for kind in ("linear", "fnn", "lstm"):
        history = study.history(kind)
        env = study.env(history=history)
        hidden = () if kind == "linear" else widths
        spec = PolicySpec(kind, history * env.obs_size, len(env.action_slots), hidden)
        policy = Policy(spec)
        theta = 0.1 * jax.random.normal(jax.random.PRNGKey(0), (policy.size,))
        params = (theta, jnp.zeros(spec.obs_size), jnp.ones(spec.obs_size))
        label = f"pars_{kind}" + (f"_{'x'.join(map(str, hidden))}" if hidden else "")
        out.append((label, env, pars_apply(policy), params, initial_carry(policy)))
    return out


def _saved_controllers(study, policies: dict):
    """[(label, env, policy_apply, params, carry)] of saved PARS policies {label: folder},
    each observing as it was trained (`experiments.evaluate.controlled_env`)."""
    from experiments.evaluate import controlled_env

    return [(label, *controlled_env(study, f"policy:{folder}"))
            for label, folder in policies.items()]


def mpc_row(study, options: str, batch: int, calls: int) -> dict:
    """The MPC's latency row: one decision (`baselines.mpc.decide`) from a faulted state."""
    env = study.env()
    planner, mpc, zeros = mpc_controller(env, parse_options(options))
    spec = study.tasks("test")[0]
    grid = jax.tree.map(jnp.asarray, study.point(spec.operating_point))
    task = jax.tree.map(lambda a: a[0], study.batch([spec]).task)
    steps = int(round((spec.fault_start + 0.3) / env.config.agent_dt))
    state = jax.jit(lambda t: env.state_after(t, study.params, grid, steps))(task)
    inputs = PlanInputs(state, grid, study.params, jnp.zeros((), jnp.int32))
    one = jax.jit(lambda plan, inputs: planner.plan(plan, inputs, mpc))
    many = jax.jit(jax.vmap(lambda plan, inputs: planner.plan(plan, inputs, mpc),
                            in_axes=(0, PlanInputs(0, None, None, None))))
    states = jax.tree.map(lambda a: jnp.broadcast_to(a, (batch,) + a.shape), state)
    single = _median_call(one, (jnp.asarray(zeros), inputs), max(3, calls // 20))
    batched = _median_call(many, (jnp.tile(zeros, (batch, 1, 1)),
                                  PlanInputs(states, grid, study.params, inputs.step)), 3)
    return {"controller": f"mpc({options or 'defaults'})", "batch": batch,
            "one_task_ms": round(1e3 * single, 2),
            "per_decision_in_batch_us": round(1e6 * batched / batch, 1)}


def bench_study(name: str, batch: int, calls: int, mpc: str | None, mpc_batch: int,
                policies: dict | None = None) -> dict:
    """Latency rows of the study `name`'s controllers: random-θ PARS policies, or the
    trained `policies` {label: folder}, then UVLS and the MPC with options `mpc` (None: no
    MPC row)."""
    study = load_study(name)
    rows = []
    pars = _saved_controllers(study, policies) if policies else _controllers(study)
    uvls_env = study.env()
    for label, env, apply, params, carry in [*pars, ("uvls", uvls_env,
                                                     *uvls_policy(uvls_env))]:
        obs = jnp.ones(env.config.history * env.obs_size)
        one = jax.jit(apply)
        many = jax.jit(jax.vmap(apply, in_axes=(None, 0, 0)))
        carries = jax.tree.map(lambda a: jnp.broadcast_to(a, (batch,) + jnp.shape(a)), carry)
        single = _median_call(one, (params, obs, carry), calls)
        batched = _median_call(many, (params, jnp.tile(obs, (batch, 1)), carries),
                               max(10, calls // 10))
        row = {"controller": label, "obs_size": int(obs.shape[0]),
               "one_task_ms": round(1e3 * single, 4),
               "per_decision_in_batch_us": round(1e6 * batched / batch, 3)}
        print(name, row, flush=True)
        rows.append(row)
    if mpc is not None:
        row = mpc_row(study, mpc, mpc_batch, calls)
        print(name, row, flush=True)
        rows.append(row)
    return {"study": name, "batch": batch, "controllers": rows}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--studies", nargs="*", default=["ieee39_fidvr", "ieee300_fidvr"],
                        help="built-in study names or study files")
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--calls", type=int, default=200)
    parser.add_argument("--mpc", default="", help="MPC options (baselines.mpc), e.g. horizon=1")
    parser.add_argument("--mpc-batch", type=int, default=32)
    parser.add_argument("--out", default="benchmarks/cpu/latency.json")
    args = parser.parse_args(argv)
    write_report(args.out, paper_s={"pars": 0.72, "mpc": 63.31},
                 studies=[bench_study(s, args.batch, args.calls, args.mpc, args.mpc_batch)
                          for s in args.studies])


if __name__ == "__main__":
    main()
