"""The decision latency of a study's controllers (`bench_study`): random-θ or trained PARS
policies, the UVLS relays and the MPC, one jitted decision for one task and per decision in
a vmapped batch; `experiments.bench.latency` (which says how each is measured) and the
reproduction's tab3 report them."""
from __future__ import annotations

import statistics
import time

import jax
import jax.numpy as jnp

from ars.normalizer import initial_carry, normalized_policy
from ars.policies import Policy, PolicySpec
from baselines.controllers import load
from baselines.mpc import mpc_controller, parse_options
from baselines.uvls import uvls_policy
from experiments.common.studyargs import study_from_spec
from experiments.common.training import paper_preset
from jaxgrid.episode import ControlInputs
from jaxgrid.problem import GridProblem


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
    widths = paper_preset(study)["hidden"]
    for kind in ("linear", "fnn", "lstm"):
        history = study.history(kind)
        env = study.env(history=history)
        hidden = () if kind == "linear" else widths
        spec = PolicySpec(kind, history * env.obs_size, len(env.action_slots), hidden)
        policy = Policy(spec)
        theta = 0.1 * jax.random.normal(jax.random.PRNGKey(0), (policy.size,))
        params = (theta, jnp.zeros(spec.obs_size), jnp.ones(spec.obs_size))
        label = f"pars_{kind}" + (f"_{'x'.join(map(str, hidden))}" if hidden else "")
        out.append((label, env, normalized_policy(policy, GridProblem.network), params,
                    initial_carry(policy)))
    return out


def _saved_controllers(study, policies: dict):
    """[(label, env, policy_apply, params, carry)] of saved PARS policies {label: folder},
    each observing as it was trained (`baselines.controllers.load`)."""
    loaded = {label: load(f"policy:{folder}", study) for label, folder in policies.items()}
    return [(label, c.env, c.apply, c.params, c.carry) for label, c in loaded.items()]


def faulted_inputs(study) -> ControlInputs:
    """What the episode gives a controller (`jaxgrid.episode.ControlInputs`) 0.3 s after the
    first test fault starts, no shedding before: the state every controller decides from
    (the MPC plans from it; a policy masking its own requests reads its bus voltages and
    time since clearing; none reads its stacked observations)."""
    env = study.env()
    spec = study.tasks("test")[0]
    grid = jax.tree.map(jnp.asarray, study.point(spec.operating_point))
    task = jax.tree.map(lambda a: a[0], study.batch([spec]).task)
    steps = int(round((spec.fault_start + 0.3) / env.config.agent_dt))
    state = jax.jit(lambda t: env.state_after(t, study.params, grid, steps))(task)
    return ControlInputs(state, grid, study.params, jnp.zeros((), jnp.int32))


def mpc_row(study, options: str, batch: int, calls: int, inputs: ControlInputs) -> dict:
    """The MPC's latency row: one decision (`baselines.mpc.decide`) from the faulted state of
    `inputs` (`faulted_inputs`)."""
    planner, mpc, zeros = mpc_controller(study.env(), parse_options(options))
    state, grid = inputs.state, inputs.grid
    one = jax.jit(lambda plan, inputs: planner.plan(plan, inputs, mpc))
    many = jax.jit(jax.vmap(lambda plan, inputs: planner.plan(plan, inputs, mpc),
                            in_axes=(0, ControlInputs(0, None, None, None))))
    states = jax.tree.map(lambda a: jnp.broadcast_to(a, (batch,) + a.shape), state)
    single = _median_call(one, (jnp.asarray(zeros), inputs), max(3, calls // 20))
    batched = _median_call(many, (jnp.tile(zeros, (batch, 1, 1)),
                                  ControlInputs(states, grid, study.params, inputs.step)), 3)
    return {"controller": f"mpc({options or 'defaults'})", "batch": batch,
            "one_task_ms": round(1e3 * single, 2),
            "per_decision_in_batch_us": round(1e6 * batched / batch, 1)}


def bench_study(name: str, batch: int, calls: int, mpc: str | None, mpc_batch: int,
                policies: dict | None = None) -> dict:
    """Latency rows of the study `name`'s controllers: random-θ PARS policies, or the
    trained `policies` {label: folder}, then UVLS and the MPC with options `mpc` (None: no
    MPC row)."""
    study = study_from_spec(name)
    rows = []
    pars = _saved_controllers(study, policies) if policies else _controllers(study)
    uvls_env = study.env()
    inputs = faulted_inputs(study)
    for label, env, apply, params, carry in [*pars, ("uvls", uvls_env,
                                                     *uvls_policy(uvls_env))]:
        obs = jnp.ones(env.config.history * env.obs_size)
        one = jax.jit(apply)
        many = jax.jit(jax.vmap(apply, in_axes=(None, 0, 0, None)))  # one state for all
        carries = jax.tree.map(lambda a: jnp.broadcast_to(a, (batch,) + jnp.shape(a)), carry)
        single = _median_call(one, (params, obs, carry, inputs), calls)
        batched = _median_call(many, (params, jnp.tile(obs, (batch, 1)), carries, inputs),
                               max(10, calls // 10))
        row = {"controller": label, "obs_size": int(obs.shape[0]),
               "one_task_ms": round(1e3 * single, 4),
               "per_decision_in_batch_us": round(1e6 * batched / batch, 3)}
        print(name, row, flush=True)
        rows.append(row)
    if mpc is not None:
        row = mpc_row(study, mpc, mpc_batch, calls, inputs)
        print(name, row, flush=True)
        rows.append(row)
    return {"study": name, "batch": batch, "controllers": rows}
