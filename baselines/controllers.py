"""Every load-shedding controller by its spec: one registry, spec prefix -> loader.

    none                  never sheds
    uvls                  under-voltage relays (`baselines.uvls`)
    mpc[:name=value,...]  model-predictive control (`baselines.mpc.MpcOptions` options)
    policy:PATH           a saved PARS policy (`ars.train`, `experiments.train`)
    ppo:PATH              a saved PPO policy (`baselines.ppo`, `experiments.train_ppo`)
    rlgc:FILE             a network the PARS study published (`baselines.rlgc`)

`load(spec, study)` gives one `Controller`: the loader of the spec's prefix (`LOADERS`) reads
what a saved policy holds, builds the study's environment once, stacking as many observations
as the policy was trained with, checks the policy's layout and inputs against it, and binds
the controller to it. A saved policy (PARS or PPO) is one format: a folder of policy.json and
policy.npz; policy.json holds "spec" (what rebuilds the network), "kind" (absent for PARS,
"ppo" for PPO) and the run's information, among it "layout" (`jaxgrid.problem.layout`: the
buses it observes and acts on) and "history"; policy.npz holds the arrays. A published network
(the study's own format) states its layout by bus numbers (`baselines.rlgc_layouts`) and picks
its inputs from the study's observation.
"""
from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable
from typing import Any

from jaxgrid.env import LoadSheddingEnv
from jaxgrid.episode import idle_controller, masked
from jaxgrid.problem import GridProblem, layout

SPECS = "none, uvls, mpc[:OPTIONS], policy:PATH, ppo:PATH or rlgc:FILE"


@dataclasses.dataclass(frozen=True)
class Controller:
    """A controller bound to the environment it observes (`load`).

    Attributes:
      spec: as given, e.g. "policy:runs/x/policy".
      env: the study's environment, stacking `history` observations.
      apply: apply(params, obs (history·n_obs,), carry, inputs) -> (action (n_action,),
        carry), the one signature of `jaxgrid.episode`.
      params: its parameters.  carry: its state at the start of an episode.
      layout: the buses a saved policy observes and acts on (`jaxgrid.problem.layout`,
        checked against env), None for the others.
      history: the observations it stacks (a saved or published policy's, as trained), None
        for the others (the study's).
      info: a saved policy's run information (policy.json), {} for the others.
      own_mask: the action mask a saved policy applies to its own requests (`load`), None
        when it applies none.  arming_level: p.u., the level below which an action bus arms
        that mask (`load`), None for none.  arming_late: s after clearing from which a bus
        of the recovery check below the recovery level arms it too (`load`), None for none.
    """

    spec: str
    env: LoadSheddingEnv
    apply: Callable
    params: Any
    carry: Any
    layout: dict | None = None
    history: int | None = None
    info: dict = dataclasses.field(default_factory=dict)
    own_mask: str | None = None
    arming_level: float | None = None
    arming_late: float | None = None


def no_control(env: LoadSheddingEnv):
    """(apply, params, carry) of a controller that never sheds (`jaxgrid.episode.
    idle_controller`)."""
    return idle_controller(len(env.action_slots)), None, None


def _none(spec: str, argument: str, study) -> Controller:
    env = study.env()
    return Controller(spec, env, *no_control(env))


def _uvls(spec: str, argument: str, study) -> Controller:
    from baselines.uvls import uvls_policy

    env = study.env()
    return Controller(spec, env, *uvls_policy(env))


def _mpc(spec: str, options: str, study) -> Controller:
    from baselines.mpc import mpc_controller, parse_options

    env = study.env()
    return Controller(spec, env, *mpc_controller(env, parse_options(options)))


def _pars(spec: str, path: str, study) -> Controller:
    from ars.checkpoint import load_policy
    from ars.normalizer import initial_carry, normalized_policy

    policy, params, info = load_policy(_saved(spec, path, None))
    env = _environment(spec, info, study, policy.spec.obs_size)
    # the network batched as in training (`jaxgrid.problem.GridProblem.network`)
    return Controller(spec, env, normalized_policy(policy, GridProblem.network), params,
                      initial_carry(policy), info.get("layout"), env.config.history, info)


def _ppo(spec: str, path: str, study) -> Controller:
    from baselines.ppo import cached_apply, load_policy

    policy, params, info = load_policy(_saved(spec, path, "ppo"))
    env = _environment(spec, info, study, policy.obs_size)
    return Controller(spec, env, cached_apply(policy), params, None, info.get("layout"),
                      env.config.history, info)


def _rlgc(spec: str, path: str, study) -> Controller:
    from baselines.rlgc import read_policy, rlgc_apply

    policy, params = read_policy(path)
    env = study.env(history=policy.history)
    return Controller(spec, env, rlgc_apply(policy, env), params,
                      policy.network.initial_carry(), history=policy.history)


# spec prefix -> loader(spec, what follows "prefix:", study) -> Controller; the study needs
# only `name` and `env(**EnvConfig changes)`
LOADERS: dict[str, Callable] = {"none": _none, "uvls": _uvls, "mpc": _mpc, "policy": _pars,
                                "ppo": _ppo, "rlgc": _rlgc}
SAVED_KINDS = {"policy": None, "ppo": "ppo"}  # prefix -> the "kind" its policy.json holds
ARGUMENT = {"none": False, "uvls": False, "mpc": None}  # takes none / may take one (else: must)


def load(spec: str, study, own_mask: bool = True, arming_level: float | None = None,
         arming_late: float | None = None) -> Controller:
    """The controller `spec` (module docstring) on `study`'s environment; ValueError naming
    the spec if it is none of `SPECS`, or a saved policy that does not fit the study.

    A saved policy trained under an action mask (policy.json's "action_mask",
    `EnvConfig.action_mask`) that the study's environment does not apply masks its own
    requests with it (`own_mask`, `jaxgrid.episode.masked`: the supervision it was trained
    with travels with it, as a relay's arming logic does), with a warning that says so;
    one trained to mask its own requests (policy.json's "self_mask", `--self-mask`) masks
    them wherever it runs, under its own mask too, as in training. A policy trained under a
    mask is armed (`jaxgrid.episode.masked`) at policy.json's "arming_level" (trained with
    `--arming-level`, or set where it is installed) or at `arming_level` (p.u.) in its place,
    wherever it runs: a setting of the policy's supervision, as a relay's is set where it is
    installed (ValueError for a policy trained without a mask); likewise its late arming
    (policy.json's "arming_late", or `arming_late`, s). own_mask=False leaves its
    requests unmasked and unarmed (they then pass otherwise than in training, which the
    warning says). [choice]; the PNNL study's policies have no mask, so neither changes
    them."""
    prefix, colon, argument = spec.partition(":")
    takes = ARGUMENT.get(prefix, True)
    if prefix not in LOADERS or (takes is False and colon) or (takes is True and not argument):
        raise ValueError(f"--controller {spec!r}: allowed {SPECS}")
    controller = LOADERS[prefix](spec, argument, study)
    trained, here = controller.info.get("action_mask", "none"), controller.env.config.action_mask
    armed = controller.info.get("self_mask", False)
    level = controller.info.get("arming_level") if arming_level is None else arming_level
    late = controller.info.get("arming_late") if arming_late is None else arming_late
    for flag, given in (("--arming-level", arming_level), ("--arming-late", arming_late)):
        if given is not None and trained == "none":
            raise ValueError(f"{flag}: {spec} was trained without an action mask, so it has "
                             "no mask to arm")
    if trained == "none" or (trained == here and not armed and level is None and late is None):
        return controller
    if trained != here:
        warnings.warn(f"{spec} was trained with action_mask = {trained!r} (study "
                      f"{controller.info.get('study')!r}); study {study.name!r} has {here!r}: "
                      + ("it masks its own requests as in training" if own_mask else
                         "its requests pass otherwise than in training (own_mask off)"),
                      stacklevel=2)
    if not own_mask:
        return controller
    return dataclasses.replace(controller, apply=masked(controller.apply, trained,
                                                        controller.env, level, late),
                               own_mask=trained, arming_level=level, arming_late=late)


def _saved(spec: str, path: str, kind: str | None) -> str:
    """`path` if it holds a saved policy of `kind`; ValueError naming the prefix that reads
    the kind it holds."""
    from ars.checkpoint import read_policy_info

    held = read_policy_info(path).get("kind")
    if held != kind:
        use = next((p for p, k in SAVED_KINDS.items() if k == held), None)
        raise ValueError(f"{path}: a {held or 'PARS'} policy: "
                         + (f"use {use}:PATH" if use else "no controller reads it"))
    return path


def _environment(spec: str, info: dict, study, obs_size: int) -> LoadSheddingEnv:
    """The study's environment stacking the saved policy's history (1 if it names none);
    ValueError naming both layouts if the policy observes or acts on other buses, or the
    policy's input size if it differs."""
    env = study.env(history=int(info.get("history", 1)))
    trained, here = info.get("layout"), layout(env.config)
    if trained is not None and trained != here:
        raise ValueError(f"{spec} (trained on study {info.get('study')!r}) has the layout "
                         f"{trained}; study {study.name!r} has {here}")
    if obs_size != env.config.history * env.obs_size:
        raise ValueError(f"{spec}: the policy observes {obs_size} values, this "
                         f"environment gives {env.config.history * env.obs_size}")
    return env
