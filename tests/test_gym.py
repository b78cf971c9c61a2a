"""The Gymnasium adapter: registration, Gymnasium's own env checker, and one episode against
the functional environment's `rollout`.

The 39-bus env runs 6 s episodes (the fault at 1 s and the 4 s recovery check still fit) and is
built once for the module; the 300-bus env is only made, reset and stepped once.
"""
from __future__ import annotations

import warnings

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from jaxgrid.env import EnvParams
from jaxgrid.gym import ENV_IDS, LoadSheddingGymEnv, training_faults  # registers the ids
from jaxgrid.simulate import FaultEvent, make_task, stack_tasks

FIDVR_FAULT = FaultEvent(4, 1.0, 0.08)  # fails recovery without control (tests/test_env.py)
# Sum of 60 float32 step rewards (gym) against the rollout's in-scan float32 sum: same
# arithmetic per step, so only the summation order can differ.
REWARD_RTOL = 1e-3


@pytest.fixture(scope="module")
def env39() -> LoadSheddingGymEnv:
    env = gymnasium.make("jaxgrid/IEEE39-FIDVR-v0", config={"episode": 6.0})
    assert isinstance(env.unwrapped, LoadSheddingGymEnv), type(env.unwrapped)
    return env.unwrapped


def test_ids_are_registered():
    for env_id in ENV_IDS:
        assert env_id in gymnasium.registry, env_id


def test_ieee39_spaces_and_default_tasks(env39):
    assert env39.observation_space.shape == (8 + 3,)
    assert env39.observation_space.dtype == np.float32
    assert env39.action_space.shape == (3,)
    assert env39.action_space.low.tolist() == [pytest.approx(-0.2)] * 3
    assert env39.action_space.high.tolist() == [0.0] * 3
    assert len(env39.tasks) == 9 and env39.tasks.count(None) == 3, \
        "buses 4, 15, 21 x durations 0 (no fault), 0.05, 0.08 s"
    assert FaultEvent(21, 1.0, 0.08) in env39.tasks


def test_check_env_passes(env39):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env39)
    allowed = "symmetric and normalized"  # the study's action range is [-0.2, 0] by design
    others = [str(w.message) for w in caught if allowed not in str(w.message)]
    assert not others, others


def test_seeded_reset_is_deterministic_and_options_pick_the_task(env39):
    drawn = [env39.reset(seed=s)[1]["task"] for s in range(40)]
    assert drawn == [env39.reset(seed=s)[1]["task"] for s in range(40)]
    assert len(set(drawn)) > 1, "different seeds draw different tasks"
    assert set(drawn) <= set(env39.tasks)
    obs, info = env39.reset(seed=0, options={"task": FIDVR_FAULT})
    assert info["task"] == FIDVR_FAULT and obs.dtype == np.float32
    assert env39.reset(options={"task": None})[1]["task"] is None
    with pytest.raises(ValueError, match="allowed 'task'"):
        env39.reset(options={"fault": FIDVR_FAULT})
    with pytest.raises(ValueError, match="FaultEvent or None"):
        env39.reset(options={"task": 4})


def test_bad_action_shape_and_bad_tasks_are_rejected(env39):
    env39.reset(seed=0)
    with pytest.raises(ValueError, match="one value per action bus"):
        env39.step(np.zeros(4, np.float32))
    with pytest.raises(ValueError, match="no default task set"):
        training_faults("ieee39")


def test_zero_action_fidvr_episode_terminates_like_rollout(env39):
    obs, _ = env39.reset(seed=0, options={"task": FIDVR_FAULT})
    total, steps, terminated, truncated = 0.0, 0, False, False
    while not (terminated or truncated):
        obs, reward, terminated, truncated, info = env39.step(np.zeros(3, np.float32))
        assert isinstance(reward, float) and isinstance(terminated, bool), (reward, terminated)
        assert obs.dtype == np.float32 and obs.shape == env39.observation_space.shape
        total += reward
        steps += 1
    assert terminated and not truncated and not info["diverged"], info
    assert reward == -1000.0 and total <= -1000.0, (reward, total)
    assert steps < env39.env.config.n_steps == 60, "failure ends the episode early"
    assert 5.0 < info["time"] < 6.0, "judged after the 4 s recovery time past clearing at 1.08 s"

    def zero_policy(params, obs, carry):
        return jnp.zeros(3), carry

    batch = stack_tasks([make_task(env39.env.model, FIDVR_FAULT)])
    out = jax.jit(env39.env.rollout, static_argnums=0)(zero_policy, None, batch, EnvParams())
    assert int(out["steps"][0]) == steps and not bool(out["recovered"][0])
    assert total == pytest.approx(float(out["reward"][0]), rel=REWARD_RTOL)


def test_step_is_compiled_once(env39):
    for fault in (None, FIDVR_FAULT, FaultEvent(15, 1.0, 0.05)):
        env39.reset(options={"task": fault})
        env39.step(env39.action_space.sample())
    assert env39._step_fn._cache_size() == 1 and env39._reset_fn._cache_size() == 1


def test_ieee300_makes_resets_and_steps():
    env = gymnasium.make("jaxgrid/IEEE300-FIDVR-v0", config={"episode": 0.2})
    assert len(env.unwrapped.tasks) == 27, "9 buses x 3 durations"
    obs, info = env.reset(seed=1)
    assert env.observation_space.contains(obs), (obs.min(), obs.max())
    assert env.action_space.shape == (34,)
    obs, reward, terminated, truncated, info = env.step(np.zeros(34, np.float32))
    assert obs.shape == env.observation_space.shape and np.isfinite(reward)
    assert not terminated and not truncated and info["time"] == pytest.approx(0.1)
