"""The Gymnasium adapter: registration, Gymnasium's own env checker, and one episode against
the functional environment's `jaxgrid.episode.play_tasks`.

The 39-bus env runs 6 s episodes (the fault at 1 s and the 4 s recovery check still fit) and is
built once for the module; the 300-bus env is only made, reset and stepped once.
"""
from __future__ import annotations

import functools
import warnings

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from jaxgrid.env import EnvParams
from jaxgrid.episode import play_tasks
from jaxgrid.gym import ENV_IDS, LoadSheddingGymEnv  # registers the ids
from jaxgrid.simulate import FaultEvent, make_task, stack_tasks
from jaxgrid.study import builtin

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
    faults = [spec.event() for spec in env39.tasks]
    assert len(faults) == 9 and faults.count(None) == 3, \
        "buses 4, 15, 21 x durations 0 (no fault), 0.05, 0.08 s"
    assert FaultEvent(21, 1.0, 0.08) in faults


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
    assert set(drawn) <= {spec.event() for spec in env39.tasks}
    obs, info = env39.reset(seed=0, options={"task": FIDVR_FAULT})
    assert info["task"] == FIDVR_FAULT and info["point"] == 0 and obs.dtype == np.float32
    assert env39.reset(options={"task": None})[1]["task"] is None
    with pytest.raises(ValueError, match=r"operating point 1: the study has 1"):
        env39.reset(options={"point": 1})
    with pytest.raises(ValueError, match="allowed 'task'"):
        env39.reset(options={"fault": FIDVR_FAULT})
    with pytest.raises(ValueError, match="FaultEvent or None"):
        env39.reset(options={"task": 4})


def test_bad_action_shape_and_bad_tasks_are_rejected(env39):
    env39.reset(seed=0)
    with pytest.raises(ValueError, match="one value per action bus"):
        env39.step(np.zeros(4, np.float32))
    with pytest.raises(ValueError, match=r"tasks\[1\] = 4 \(int\): must be a TaskSpec"):
        LoadSheddingGymEnv(env39.study, tasks=[None, 4])
    with pytest.raises(ValueError, match="needs study=NAME"):
        gymnasium.make("jaxgrid/FIDVR-v0")


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

    def zero_policy(params, obs, carry, inputs):
        return jnp.zeros(3), carry

    grid = env39.study.point(0)
    batch = stack_tasks([make_task(grid, FIDVR_FAULT)])
    out = jax.jit(functools.partial(play_tasks, env39.env), static_argnums=0)(
        zero_policy, None, batch, EnvParams(), grid)
    assert int(out["steps"][0]) == steps and not bool(out["recovered"][0])
    assert total == pytest.approx(float(out["reward"][0]), rel=REWARD_RTOL)


def test_step_is_compiled_once_across_operating_points():
    env = gymnasium.make("jaxgrid/FIDVR-v0", study=builtin("ieee39_fidvr", (0.9, 1.1)),
                         config={"episode": 0.3}).unwrapped
    assert {spec.operating_point for spec in env.tasks} == {0, 1}, "the training set, 2 points"
    volts = []
    for point, fault in ((0, None), (1, FIDVR_FAULT), (1, FaultEvent(15, 1.0, 0.05))):
        obs, info = env.reset(options={"task": fault, "point": point})
        assert info["point"] == point
        volts.append(obs[:8])
        env.step(env.action_space.sample())
    assert env._step_fn._cache_size() == 1 and env._reset_fn._cache_size() == 1
    assert np.abs(volts[0] - volts[1]).max() > 1e-3, "the load levels start at other voltages"


def test_ieee300_makes_resets_and_steps():
    env = gymnasium.make("jaxgrid/IEEE300-FIDVR-v0", config={"episode": 0.2})
    assert len(env.unwrapped.tasks) == 27, "9 buses x 3 durations"
    obs, info = env.reset(seed=1)
    assert env.observation_space.contains(obs), (obs.min(), obs.max())
    assert env.action_space.shape == (34,)
    obs, reward, terminated, truncated, info = env.step(np.zeros(34, np.float32))
    assert obs.shape == env.observation_space.shape and np.isfinite(reward)
    assert not terminated and not truncated and info["time"] == pytest.approx(0.1)
