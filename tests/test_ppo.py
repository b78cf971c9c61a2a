"""The PPO baseline (`baselines.ppo`, `baselines.ppo_train`, `experiments.train_ppo`): the
gymnax adapter steps as the functional env does, at the drawn task's operating point; the
losses equal a hand computation; a run killed after a chunk resumes to the state of an
uninterrupted one; the saved policy evaluates through `experiments.evaluate --controller
ppo:PATH` and a layout mismatch is named. rejax's own PPO learning is rejax's test
(CartPole); nothing here trains for long. Tiny settings (0.3 s episodes, 4 envs × 3 steps)
keep it to a few compiles."""
from __future__ import annotations

import json
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import orbax.checkpoint as ocp
import pytest
from rejax.algos.ppo import AdvantageMinibatch, Trajectory

from baselines.ppo import PPOConfig, make_ppo
from experiments import evaluate, train_ppo
from jaxgrid.gym import gymnax_env
from jaxgrid.study import builtin

# float32 throughout: values of O(1) to O(1e5) through a dozen operations and a mean over a
# handful of samples differ from float64 numpy by a few 1e-7 relative; 1e-5 keeps a margin
# and is far below the smallest loss term checked (> 1e-2).
RTOL = 1e-5
# the adapter and the env run the same float32 step in differently fused graphs
OBS_ATOL = 1e-5   # p.u.

TINY = ["--envs", "4", "--rollout-steps", "3", "--epochs", "2", "--minibatches", "2",
        "--eval-every", "1", "--seed", "3"]


@pytest.fixture(scope="module")
def two_points():
    # the faults (at 1.0 s) moved inside the short episode, as a study must have them
    return builtin("ieee39_fidvr", (0.9, 1.0), env={"episode": 0.3},
                   tasks={name: {"fault_starts": (0.1,)} for name in ("train", "test")})


def test_adapter_resets_and_steps_as_the_env_at_the_drawn_task(two_points):
    study = two_points
    env, params = gymnax_env(study)
    specs = study.tasks("train")
    # a key that draws a fault at the second operating point (the gather must pick it)
    key = next(k for k in jax.random.split(jax.random.PRNGKey(0), 64)
               if (s := specs[int(jax.random.randint(k, (), 0, len(specs)))]).operating_point
               == 1 and s.fault_duration > 0)
    spec = specs[int(jax.random.randint(key, (), 0, len(specs)))]
    obs, state = env.reset(key, params)
    inner, grid = env.env, study.point(1)
    task = study.batch([spec]).task
    task = jax.tree.map(lambda a: a[0], task)
    ref_obs, ref_state = jax.jit(inner.reset)(None, task, study.params, grid)
    np.testing.assert_allclose(obs, ref_obs, atol=OBS_ATOL)
    assert int(state.point) == 1

    ref_step = jax.jit(inner.step)
    total = 0.0
    for k, policy_action in enumerate(([-1.0, 0.0, 1.0], [0.0, -1.0, -1.0], [1.0, 1.0, 1.0])):
        env_action = -0.2 + (np.array(policy_action) + 1.0) * 0.1  # [-1, 1] onto [-0.2, 0]
        obs, state, reward, done, _ = env.step(jax.random.PRNGKey(k), state,
                                               jnp.array(policy_action), params)
        ref_obs, ref_state, ref_reward, ref_done, _ = ref_step(ref_state, jnp.array(env_action),
                                                               study.params, grid)
        total += float(ref_reward)
        np.testing.assert_allclose(reward, ref_reward, rtol=RTOL, atol=1e-3)
        assert bool(done) == bool(ref_done)
        if not done:
            np.testing.assert_allclose(obs, ref_obs, atol=OBS_ATOL)
            np.testing.assert_allclose(state.inner.grid.load_left, ref_state.grid.load_left,
                                       atol=1e-6)
    assert bool(done), "0.3 s episode: done after 3 agent steps"
    assert int(state.time) == 0, "gymnax resets when the episode ends"
    assert int(state.returns_count) == 1
    np.testing.assert_allclose(state.returns_sum, total, rtol=RTOL)


def _hand_params(template, last_bias, log_std=None):
    """Every weight zero, the output layer's bias `last_bias`: the net outputs it for any
    observation (tanh(0) = 0 in the hidden layers)."""
    params = jax.tree.map(jnp.zeros_like, template)
    inner = dict(params["params"])
    last = "action_mean" if "action_mean" in inner else \
        max((k for k in inner if k.startswith("Dense_")), key=lambda k: int(k[6:]))
    inner[last] = {**inner[last], "bias": jnp.asarray(last_bias, jnp.float32)}
    if log_std is not None:
        inner["action_log_std"] = jnp.asarray(log_std, jnp.float32)
    return {"params": inner}


def test_losses_equal_a_hand_computation(two_points):
    env, params = gymnax_env(two_points)
    algo = make_ppo(env, params, PPOConfig(envs=2, rollout_steps=3, minibatches=1))
    algo = algo.replace(ent_coef=0.05, kl_coef=0.3, vf_coef=0.7)
    key = jax.random.PRNGKey(0)
    obs = jax.random.normal(key, (6, env.n_obs))
    mu, log_sigma = np.array([0.1, -0.4, 0.3]), np.array([-0.5, 0.0, 0.2])
    actor = _hand_params(algo.actor.init(key, obs[:1], key), mu, log_sigma)
    action = np.array([[0.0, 0.0, 0.0], [0.5, -1.0, 0.2], [-0.3, 0.4, 1.1],
                       [0.1, -0.4, 0.3], [1.0, 1.0, -1.0], [-0.8, 0.2, 0.0]], np.float32)
    sigma = np.exp(log_sigma)
    log_prob = np.sum(-(action - mu) ** 2 / (2 * sigma ** 2) - log_sigma
                      - 0.5 * np.log(2 * np.pi), axis=1)
    entropy = np.sum(0.5 + 0.5 * np.log(2 * np.pi) + log_sigma)
    ratio = np.array([0.5, 0.9, 1.0, 1.1, 1.6, 2.0])  # 0.5, 1.6, 2.0 outside 1 ± 0.3
    old_log_prob = log_prob - np.log(ratio)
    advantages = np.array([1.0, -2.0, 0.5, 3.0, -1.0, 2.5])
    adv = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    surrogate = np.minimum(ratio * adv, np.clip(ratio, 0.7, 1.3) * adv).mean()
    kl = np.mean(ratio - 1 - np.log(ratio))
    want_actor = -surrogate - 0.05 * entropy + 0.3 * kl

    value = 150.0
    critic = _hand_params(algo.critic.init(key, obs[:1]), [value])
    old_value = np.array([0.0, -100.0, 400.0, 149.0, 700.0, 160.0])  # 2 moves > 200 clipped
    targets = np.array([100.0, 300.0, 500.0, -20.0, 900.0, 150.0])
    clipped = old_value + np.clip(value - old_value, -200, 200)
    want_critic = 0.7 * np.mean(np.maximum((value - targets) ** 2, (clipped - targets) ** 2))

    f32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    batch = AdvantageMinibatch(
        Trajectory(obs=obs, action=f32(action), log_prob=f32(old_log_prob),
                   reward=jnp.zeros(6), value=f32(old_value), done=jnp.zeros(6, bool)),
        advantages=f32(advantages), targets=f32(targets))
    np.testing.assert_allclose(algo.actor_loss(actor, batch), want_actor, rtol=RTOL)
    np.testing.assert_allclose(algo.critic_loss(critic, batch), want_critic, rtol=RTOL)
    # the clip and the KL matter: without them the losses differ
    assert abs(float(algo.replace(kl_coef=0.0).actor_loss(actor, batch)) - want_actor) > 1e-2
    assert abs(float(algo.replace(vf_clip=1e6).critic_loss(critic, batch))
               - want_critic) > 1.0


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The training flags: the 39-bus study with 0.3 s episodes (a study file, so the run
    folder's study.toml has them too) and tiny PPO settings."""
    study = tmp_path_factory.mktemp("study") / "short.toml"
    study.write_text('name = "ieee39_short"\n[grid]\nbuiltin = "ieee39_fidvr"\n'
                     '[env]\nepisode = 0.3\n[tasks.train]\nfault_starts = [0.1]\n'
                     '[tasks.test]\nfault_starts = [0.1]\n')
    return ["--study", str(study)] + TINY


@pytest.fixture(scope="module")
def straight(tmp_path_factory, tiny):
    out = tmp_path_factory.mktemp("straight")
    assert train_ppo.main(tiny + ["--env-steps", "24", "--out", str(out)]) == 0
    return out


def _checkpoint(folder, step):
    return ocp.StandardCheckpointer().restore((folder / "checkpoints" / str(step) / "state")
                                              .absolute())


def _rows(folder):
    rows = [json.loads(line) for line in (folder / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in r.items() if not k.startswith("wall")} for r in rows]


def test_a_run_killed_after_one_chunk_resumes_to_the_uninterrupted_state(straight, tiny,
                                                                          tmp_path):
    assert [r["iteration"] for r in _rows(straight)] == [1, 2]
    assert _rows(straight)[0]["env_steps"] == 12
    # the run as it was when killed after the first chunk: its checkpoint and metrics line
    killed = tmp_path / "killed"
    shutil.copytree(straight, killed)
    shutil.rmtree(killed / "checkpoints" / "2")
    shutil.rmtree(killed / "policy")
    lines = (killed / "metrics.jsonl").read_text().splitlines()
    (killed / "metrics.jsonl").write_text(lines[0] + "\n")
    assert train_ppo.main(tiny + ["--env-steps", "20", "--out", str(killed)]) == 2, \
        "a folder with a run needs --resume"
    assert train_ppo.main(tiny + ["--env-steps", "24", "--resume", "--out", str(killed)]) == 0
    assert _rows(killed) == _rows(straight)
    a, b = _checkpoint(straight, 2), _checkpoint(killed, 2)
    assert jax.tree.structure(a) == jax.tree.structure(b)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(x, y)  # bitwise: the same compiled iterations
    for name in ("policy.npz", "policy.json"):
        assert (killed / "policy" / name).read_bytes() == (straight / "policy" / name)\
            .read_bytes()
    config = json.loads((straight / "config.json").read_text())
    assert config["config"]["vf_clip"] == 200.0 and config["iterations"] == 2


def test_evaluate_runs_the_saved_policy_and_names_a_layout_mismatch(straight, tmp_path, capsys):
    out = tmp_path / "results.json"
    assert evaluate.main(["--study", str(straight / "study.toml"), "--controller",
                          f"ppo:{straight / 'policy'}", "--tasks", "train",
                          "--out", str(out)]) == 0
    summary = json.loads(out.read_text())["summary"]
    assert summary["n_tasks"] == 9
    # the same deterministic policy on the same tasks as the run's last evaluation
    np.testing.assert_allclose(summary["mean_reward"], _rows(straight)[-1]["reward_mean"],
                               rtol=RTOL)
    other = tmp_path / "other.toml"
    other.write_text('name = "fewer_buses"\n[grid]\nbuiltin = "ieee39_fidvr"\n'
                     '[env]\nobserved_buses = [4, 504, 7, 507]\n')
    assert evaluate.main(["--study", str(other), "--controller", f"ppo:{straight / 'policy'}",
                          "--out", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "layout" in err and "fewer_buses" in err and "[4, 504, 7, 507]" in err
    assert evaluate.main(["--study", str(other), "--controller", f"ppo:{tmp_path}",
                          "--out", str(tmp_path / "x.json")]) == 2
    assert "not a saved policy folder" in capsys.readouterr().err
    assert evaluate.main(["--study", str(other), "--controller", f"policy:{straight / 'policy'}",
                          "--out", str(tmp_path / "x.json")]) == 2
    assert "use ppo:PATH" in capsys.readouterr().err


def test_the_saved_policy_acts_with_the_mean_of_rejax_gaussian():
    """GaussianMeanPolicy has rejax's GaussianPolicy parameters; its `mean` is the action
    rejax's own `act` samples once the spread is ~0."""
    from rejax.networks import GaussianPolicy

    from baselines.ppo import PolicyInfo

    info = PolicyInfo(obs_size=5, action_dim=3, hidden=(8,), activation="tanh",
                      action_low=-0.2, action_high=0.0, normalize_actions=True)
    actor, obs = info.actor(), jax.random.normal(jax.random.PRNGKey(1), (4, 5))
    params = actor.init(jax.random.PRNGKey(0), obs, jax.random.PRNGKey(2))
    rejax = GaussianPolicy(3, (-1.0, 1.0), (8,), jax.nn.tanh)
    assert jax.tree.structure(params) == jax.tree.structure(
        rejax.init(jax.random.PRNGKey(0), obs, jax.random.PRNGKey(2)))
    still = jax.tree_util.tree_map_with_path(
        lambda path, x: jnp.full_like(x, -60.0) if "action_log_std" in str(path) else x, params)
    sampled = rejax.apply(still, obs, jax.random.PRNGKey(3), method="act")
    np.testing.assert_allclose(actor.apply(still, obs, method="mean").clip(-1.0, 1.0), sampled,
                               atol=1e-6)
