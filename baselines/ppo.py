"""PPO baseline of the PNNL PARS study: rejax's PPO on the gymnax face of `LoadSheddingEnv`
(`jaxgrid.gym.LoadSheddingGymnax`).

The study (Huang et al., "Accelerated deep reinforcement learning based load shedding for
emergency voltage control", 2022) compares PARS with parallel PPO (RLlib, Table II). Here PPO
is rejax 0.1.3's (keraJLi/rejax, `rejax/algos/ppo.py`: clipped surrogate, GAE, separate actor
and critic MLPs each with its own Adam, observation normalisation), with what Table II uses
and rejax lacks added by overriding its two update functions:

  - the value clip of RLlib (`vf_clip_param`): the new value may move at most `vf_clip`
    (reward units) from the value at collection; rejax clips it with the policy's clip_eps;
  - the KL term of RLlib (`kl_coeff` · mean KL(old ‖ new)) added to the actor loss.

    env, params = gymnax_env(study)       # jaxgrid.gym: the study's training tasks
    algo = make_ppo(env, params, PPOConfig())
    state = algo.init_state(jax.random.PRNGKey(0))
    state = algo.train_iteration(state)                 # one rollout + the epochs over it
    apply, policy_params, carry = ppo_policy(state, algo)   # the deterministic controller

Hyper-parameters (`PPOConfig`). Table II of the study: hidden layers [64, 64], learning rate
5e-4, clip 0.3, entropy coefficient 1e-4, value clip 200. Not in the table, RLlib's (ray 1.x
PPO) defaults: KL coefficient 0.2 (fixed here: RLlib adapts it towards kl_target = 0.01
after every iteration, we do not), γ = 0.99, GAE λ = 1.0, 30 epochs (num_sgd_iter), 4000
transitions per iteration (train_batch_size: 40 envs × 100 steps, one 10 s episode each) in
minibatches of 125 (≈ sgd_minibatch_size 128), value loss coefficient 1.0, no gradient
clipping, tanh activations, and actions normalised as RLlib's `normalize_actions` does (the
policy acts in [-1, 1], mapped linearly onto [action_low, action_high]). So the untrained
policy's mean action is the middle of the range, shedding 10 % of each action bus's load per
step on the study's range [-0.2, 0] (PARS's policies start at no shedding).

Differences from RLlib that remain (rejax's design, kept):
  - the log std of the Gaussian is one free parameter per action (RLlib: an output of the
    network, `free_log_std` off), initialised at 0;
  - actor and critic are separate networks with separate Adam optimisers (RLlib's default
    `vf_share_layers` is off too, but one optimiser minimises the summed loss; with separate
    Adams the value loss coefficient barely matters, Adam being scale invariant);
  - advantages are standardised per minibatch (RLlib: over the whole train batch);
  - the KL is the sample estimate k3 = (r − 1) − log r, r = π_new(a)/π_old(a), averaged over
    the minibatch's actions (drawn from the old policy), not the analytic KL of the two
    Gaussians: the old distribution's parameters are not in rejax's trajectories. k3 is
    non-negative and its expectation and expected gradient are those of KL(old ‖ new)
    (J. Schulman, "Approximating KL divergence", 2020);
  - episodes run to their end inside the fixed-length rollouts (gymnax auto-resets), the
    value of the state after a truncated episode is not bootstrapped (rejax treats `done`
    alike, as RLlib did before its `truncated` flag).
Observation normalisation is on, as in PARS (running mean and variance over every
observation collected, rejax's `NormalizeObservationsMixin`). Rewards are not normalised.
The environment must be float32 (the policy and the running statistics are).
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import chex
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from flax import traverse_util
from gymnax.environments import environment
from rejax import PPO as RejaxPPO
from rejax.networks import GaussianPolicy

from jaxgrid.env import LoadSheddingEnv

# --------------------------------------------------------------------------- #
# PPO with RLlib's value clip and KL term
# --------------------------------------------------------------------------- #


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    """Hyper-parameters (module docstring: Table II of the study, else RLlib's defaults).

    Attributes:
      envs: parallel environments.  rollout_steps: agent steps per env per iteration
        (transitions per iteration: envs · rollout_steps).
      epochs: passes over an iteration's transitions.  minibatches: per epoch.
      learning_rate: Adam, actor and critic.  clip: ε of the clipped surrogate.
      entropy: entropy coefficient.  kl_coef: coefficient of KL(old ‖ new) (fixed).
      vf_clip: largest change of the value from its value at collection (reward units).
      vf_coef: value loss coefficient.  hidden: layer widths (actor and critic).
      activation: a `flax.linen` activation name.  gamma: discount.  gae_lambda: GAE λ.
      normalize_actions: the policy acts in [-1, 1] (RLlib's normalize_actions).
      seed: PRNG seed.
    """

    envs: int = 40
    rollout_steps: int = 100
    epochs: int = 30
    minibatches: int = 32
    learning_rate: float = 5e-4
    clip: float = 0.3
    entropy: float = 1e-4
    kl_coef: float = 0.2
    vf_clip: float = 200.0
    vf_coef: float = 1.0
    hidden: tuple[int, ...] = (64, 64)
    activation: str = "tanh"
    gamma: float = 0.99
    gae_lambda: float = 1.0
    normalize_actions: bool = True
    seed: int = 0

    def __post_init__(self):
        checks = {
            "envs": (self.envs >= 1, ">= 1"), "rollout_steps": (self.rollout_steps >= 1, ">= 1"),
            "epochs": (self.epochs >= 1, ">= 1"),
            "minibatches": (self.minibatches >= 1 and
                            (self.envs * self.rollout_steps) % self.minibatches == 0,
                            f"a divisor of envs·rollout_steps = {self.envs * self.rollout_steps}"),
            "learning_rate": (self.learning_rate > 0, "> 0"), "clip": (self.clip > 0, "> 0"),
            "entropy": (self.entropy >= 0, ">= 0"), "kl_coef": (self.kl_coef >= 0, ">= 0"),
            "vf_clip": (self.vf_clip > 0, "> 0"), "vf_coef": (self.vf_coef > 0, "> 0"),
            "hidden": (all(h >= 1 for h in self.hidden), "widths >= 1"),
            "gamma": (0 < self.gamma <= 1, "in (0, 1]"),
            "gae_lambda": (0 <= self.gae_lambda <= 1, "in [0, 1]"),
        }
        for name, (ok, allowed) in checks.items():
            if not ok:
                raise ValueError(f"PPOConfig.{name} = {getattr(self, name)!r}: must be {allowed}")

    @property
    def batch(self) -> int:
        """Transitions (env steps) per iteration."""
        return self.envs * self.rollout_steps


def actor_loss(log_prob, old_log_prob, entropy, advantages, clip, entropy_coef, kl_coef):
    """The actor's loss on a minibatch (B,): −clipped surrogate − entropy_coef·mean entropy
    + kl_coef·mean k3, k3 = (r − 1) − log r the sample estimate of KL(old ‖ new),
    r = exp(log_prob − old_log_prob); advantages standardised over the minibatch."""
    log_ratio = log_prob - old_log_prob
    ratio = jnp.exp(log_ratio)
    adv = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    surrogate = jnp.minimum(ratio * adv, jnp.clip(ratio, 1 - clip, 1 + clip) * adv).mean()
    kl = ((ratio - 1.0) - log_ratio).mean()
    return -surrogate - entropy_coef * entropy.mean() + kl_coef * kl


def critic_loss(value, old_value, targets, vf_clip, vf_coef):
    """The critic's loss on a minibatch (B,), RLlib's form: vf_coef · mean max((v − R)²,
    (v_c − R)²), v_c = old_value + clip(v − old_value, ±vf_clip), R the GAE targets."""
    clipped = old_value + jnp.clip(value - old_value, -vf_clip, vf_clip)
    return vf_coef * jnp.maximum(jnp.square(value - targets),
                                 jnp.square(clipped - targets)).mean()


class PPO(RejaxPPO):
    """rejax's PPO with RLlib's value clip (`vf_clip`) and KL term (`kl_coef`); only the
    two update functions differ (module docstring). Build it with `make_ppo`."""

    vf_clip: chex.Scalar = struct.field(pytree_node=True, default=200.0)
    kl_coef: chex.Scalar = struct.field(pytree_node=True, default=0.2)

    def actor_loss(self, params, batch):
        """`actor_loss` of the minibatch `batch` (rejax's AdvantageMinibatch)."""
        t = batch.trajectories
        log_prob, entropy = self.actor.apply(params, t.obs, t.action, method="log_prob_entropy")
        return actor_loss(log_prob, t.log_prob, entropy, batch.advantages, self.clip_eps,
                          self.ent_coef, self.kl_coef)

    def critic_loss(self, params, batch):
        """`critic_loss` of the minibatch `batch`."""
        value = self.critic.apply(params, batch.trajectories.obs)
        return critic_loss(value, batch.trajectories.value, batch.targets, self.vf_clip,
                           self.vf_coef)

    def update_actor(self, ts, batch):
        grads = jax.grad(self.actor_loss)(ts.actor_ts.params, batch)
        return ts.replace(actor_ts=ts.actor_ts.apply_gradients(grads=grads))

    def update_critic(self, ts, batch):
        grads = jax.grad(self.critic_loss)(ts.critic_ts.params, batch)
        return ts.replace(critic_ts=ts.critic_ts.apply_gradients(grads=grads))


def make_ppo(env: environment.Environment, env_params, config: PPOConfig) -> PPO:
    """The PPO of `config` on a gymnax `env` (any: `jaxgrid.gym.LoadSheddingGymnax`, or
    gymnax's Pendulum-v1). Observation normalisation on, reward normalisation off.
    ValueError for a load-shedding environment that is not float32."""
    inner = getattr(env, "env", None)
    if isinstance(inner, LoadSheddingEnv) and inner.precision != "float32":
        raise ValueError(f"PPO trains float32 environments; this study is "
                         f"{inner.precision!r} (compile it with precision = 'float32')")
    return PPO.create(
        env=env, env_params=env_params, num_envs=config.envs, num_steps=config.rollout_steps,
        num_epochs=config.epochs, num_minibatches=config.minibatches,
        learning_rate=config.learning_rate, clip_eps=config.clip, ent_coef=config.entropy,
        kl_coef=config.kl_coef, vf_clip=config.vf_clip, vf_coef=config.vf_coef,
        gamma=config.gamma, gae_lambda=config.gae_lambda, normalize_observations=True,
        normalize_rewards=False, skip_initial_evaluation=True,
        agent_kwargs={"hidden_layer_sizes": tuple(config.hidden),
                      "activation": config.activation})


# --------------------------------------------------------------------------- #
# The trained policy as a controller, saved and loaded
# --------------------------------------------------------------------------- #


class GaussianMeanPolicy(GaussianPolicy):
    """rejax's GaussianPolicy (the same parameters) with the deterministic action a trained
    policy takes: its mean. rejax's public methods only sample (`act`, `__call__`)."""

    def mean(self, obs):
        """(batch, action_dim) mean action of (batch, obs_size) observations."""
        return self.action_mean(self.features(obs))


@dataclasses.dataclass(frozen=True)
class PolicyInfo:
    """What rebuilds a saved PPO actor (the `policy.json` "spec").

    Attributes:
      obs_size, action_dim: sizes.  hidden: layer widths.  activation: flax.linen name.
      action_low, action_high: the env's action range.  normalize_actions: the policy acts
        in [-1, 1] (mapped onto the range).
    """

    obs_size: int
    action_dim: int
    hidden: tuple[int, ...]
    activation: str
    action_low: float
    action_high: float
    normalize_actions: bool

    def actor(self) -> GaussianMeanPolicy:
        import flax.linen as nn

        bounds = (-1.0, 1.0) if self.normalize_actions else (self.action_low, self.action_high)
        return GaussianMeanPolicy(self.action_dim, bounds, tuple(self.hidden),
                                  getattr(nn, self.activation))


def policy_info(algo: PPO) -> PolicyInfo:
    """The PolicyInfo of a PPO built on the adapter."""
    env = algo.env.env if hasattr(algo.env, "env") else algo.env  # rejax's FloatObsWrapper
    return PolicyInfo(env.n_obs, env.n_action, tuple(algo.actor.hidden_layer_sizes),
                      algo.actor.activation.__name__, env.low, env.high, env.normalize_actions)


def make_apply(info: PolicyInfo):
    """policy_apply(params, obs (obs_size,), carry, inputs) -> (action (action_dim,), carry):
    the Gaussian's mean of the normalised observation, clipped to the policy's bounds and
    mapped onto [action_low, action_high] (`inputs` unused); params = {"actor", "obs_mean",
    "obs_var"}."""
    actor = info.actor()
    low, high = actor.action_range

    def apply(params, obs, carry, inputs):
        x = (obs - params["obs_mean"]) / jnp.sqrt(params["obs_var"] + 1e-8)  # rejax's form
        mean = actor.apply(params["actor"], x[None], method="mean")[0]
        action = jnp.clip(mean, low, high)
        if info.normalize_actions:
            action = info.action_low + (action + 1.0) * (0.5 * (info.action_high -
                                                               info.action_low))
        return action, carry

    return apply


_APPLY: dict = {}


def cached_apply(info: PolicyInfo):
    """`make_apply(info)`, one function per architecture, so repeated evaluations
    (`jaxgrid.problem.play_specs` caches by function) reuse their compilation."""
    if info not in _APPLY:
        _APPLY[info] = make_apply(info)
    return _APPLY[info]


def policy_params(state) -> dict:
    """{"actor", "obs_mean", "obs_var"} of a rejax PPO train state."""
    return {"actor": state.actor_ts.params, "obs_mean": state.obs_rms_state.mean,
            "obs_var": state.obs_rms_state.var}


def ppo_policy(source, algo: PPO | None = None):
    """(policy_apply, params, carry) of a trained PPO: `source` a saved policy folder or a
    rejax train state (then `algo` gives the architecture). Feed-forward: the carry is None."""
    if isinstance(source, (str, Path)):
        info, params, _ = load_policy(source)
    else:
        info, params = policy_info(algo), policy_params(source)
    return cached_apply(info), params, None


def save_policy(directory: str | Path, algo: PPO, state, extra: dict) -> None:
    """policy.json ({"kind": "ppo", "spec": PolicyInfo, **extra}) and policy.npz (the actor's
    arrays by path, "obs_mean", "obs_var") in `directory`, readable without orbax."""
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    info = policy_info(algo)
    (folder / "policy.json").write_text(json.dumps(
        {"kind": "ppo", "spec": dataclasses.asdict(info), **extra}, indent=1))
    params = jax.device_get(policy_params(state))
    flat = traverse_util.flatten_dict(params["actor"], sep="/")
    np.savez(folder / "policy.npz", obs_mean=params["obs_mean"], obs_var=params["obs_var"],
             **{f"actor/{k}": np.asarray(v) for k, v in flat.items()})


def load_policy(directory: str | Path):
    """(PolicyInfo, params, info dict) of a folder written by `save_policy`."""
    from ars.checkpoint import read_policy_info

    folder = Path(directory)
    meta = read_policy_info(folder)
    if meta.get("kind") != "ppo":
        raise ValueError(f"{folder}: not a PPO policy (kind {meta.get('kind')!r}); use "
                         "policy:PATH for PARS policies")
    info = PolicyInfo(**{**meta["spec"], "hidden": tuple(meta["spec"]["hidden"])})
    template = info.actor().init(jax.random.PRNGKey(0), jnp.zeros((1, info.obs_size)),
                                 jax.random.PRNGKey(0))
    want = traverse_util.flatten_dict(template, sep="/")
    arrays = np.load(folder / "policy.npz")
    flat = {}
    for key, value in want.items():
        saved = arrays.get(f"actor/{key}")
        if saved is None or saved.shape != value.shape:
            raise ValueError(f"{folder}: actor array {key} is "
                             f"{None if saved is None else saved.shape}, the policy in "
                             f"policy.json needs {value.shape}")
        flat[key] = saved
    params = {"actor": traverse_util.unflatten_dict(flat, sep="/"),
              "obs_mean": arrays["obs_mean"], "obs_var": arrays["obs_var"]}
    return info, params, meta
