"""Every load-shedding controller by its spec, and the saved-policy format they share.

    none                  never sheds
    uvls                  under-voltage relays (`baselines.uvls`)
    mpc[:name=value,...]  model-predictive control (`baselines.mpc.MpcOptions` options)
    policy:PATH           a saved PARS policy (`ars.train`, `experiments.train`)
    ppo:PATH              a saved PPO policy (`baselines.ppo`, `experiments.train_ppo`)
    rlgc:FILE             a network the PARS study published (`baselines.rlgc`)

A saved policy is a folder of policy.json and policy.npz: policy.json holds "spec" (what
rebuilds the network), "kind" (absent for PARS, "ppo" for PPO) and the run's information,
among it "layout" (`jaxgrid.problem.layout`: the buses it observes and acts on, checked
against the study it is evaluated on) and "history"; policy.npz holds the arrays. A published
network states its own layout by bus numbers (`baselines.rlgc_layouts`) and picks its inputs
from the study's observation. `controller(spec, env)` gives (policy_apply, params, carry)
for `jaxgrid.episode.play_tasks`; every policy_apply is a controller of its one signature,
policy_apply(params, obs, carry, inputs) -> (action, carry).
"""
from __future__ import annotations

import jax.numpy as jnp

from jaxgrid.env import LoadSheddingEnv
from jaxgrid.problem import GridProblem, layout
from jaxgrid.study import Study

SPECS = "none, uvls, mpc[:OPTIONS], policy:PATH, ppo:PATH or rlgc:FILE"
SAVED_KINDS = {"policy:": None, "ppo:": "ppo"}  # spec prefix -> the "kind" policy.json holds


def no_control(env: LoadSheddingEnv):
    """(policy_apply, params, carry) of a controller that never sheds."""
    n = len(env.action_slots)
    return (lambda params, obs, carry, inputs: (jnp.zeros(n), carry)), None, None


def saved_policy(control: str):
    """(Policy, (θ, mean, std), info) of a "policy:PATH" controller, (PolicyInfo, params,
    info) of a "ppo:PATH" one, (RlgcPolicy, params, {"history"}) of a "rlgc:FILE" one, read
    once; else None. ValueError if PATH holds no saved policy or one of the other kind."""
    if control.startswith("rlgc:"):
        from baselines.rlgc import read_policy
        policy, params = read_policy(control.removeprefix("rlgc:"))
        return policy, params, {"history": policy.history}
    prefix = next((p for p in SAVED_KINDS if control.startswith(p)), None)
    if prefix is None:
        return None
    from ars.checkpoint import read_policy_info

    path = control.removeprefix(prefix)
    kind = read_policy_info(path).get("kind")
    if kind != SAVED_KINDS[prefix]:
        use = next((p for p, k in SAVED_KINDS.items() if k == kind), None)
        raise ValueError(f"{path}: a {kind or 'PARS'} policy: "
                         + (f"use {use}PATH" if use else "no controller reads it"))
    if kind == "ppo":
        from baselines.ppo import load_policy as load_ppo
        return load_ppo(path)
    from ars.checkpoint import load_policy
    return load_policy(path)


def check_layout(control: str, info: dict, study: Study, env: LoadSheddingEnv) -> None:
    """ValueError naming both layouts if a saved policy observes or acts on other buses."""
    trained = info.get("layout")
    here = layout(env.config)
    if trained is not None and trained != here:
        raise ValueError(f"{control} (trained on study {info.get('study')!r}) has the layout "
                         f"{trained}; study {study.name!r} has {here}")


def pars_apply(policy):
    """policy_apply of a PARS `ars.policies.Policy` with its observation normaliser, the
    network batched as in training (`jaxgrid.problem.GridProblem.network`)."""
    from ars.normalizer import normalized_policy

    return normalized_policy(policy, GridProblem.network)


def controller(spec: str, env: LoadSheddingEnv, saved=None):
    """(policy_apply, params, carry) of the controller `spec` (module docstring) on `env`;
    `saved`: a saved policy as `saved_policy` returns it, read from PATH if not given."""
    if spec == "none":
        return no_control(env)
    if spec == "uvls":
        from baselines.uvls import uvls_policy
        return uvls_policy(env)
    if spec == "mpc" or spec.startswith("mpc:"):
        from baselines.mpc import mpc_controller, parse_options
        return mpc_controller(env, parse_options(spec.removeprefix("mpc").removeprefix(":")))
    if spec.startswith("policy:"):
        from ars.normalizer import initial_carry
        policy, params, _ = saved or saved_policy(spec)
        _check_inputs(spec, policy.spec.obs_size, env)
        return pars_apply(policy), params, initial_carry(policy)
    if spec.startswith("ppo:"):
        from baselines.ppo import cached_apply
        info, params, _ = saved or saved_policy(spec)
        _check_inputs(spec, info.obs_size, env)
        return cached_apply(info), params, None
    if spec.startswith("rlgc:"):
        from baselines.rlgc import rlgc_apply
        policy, params, _ = saved or saved_policy(spec)
        return rlgc_apply(policy, env), params, policy.network.initial_carry()
    raise ValueError(f"--controller {spec!r}: allowed {SPECS}")


def _check_inputs(spec: str, obs_size: int, env: LoadSheddingEnv) -> None:
    if obs_size != env.config.history * env.obs_size:
        raise ValueError(f"{spec}: the policy observes {obs_size} values, this "
                         f"environment gives {env.config.history * env.obs_size}")
