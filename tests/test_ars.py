"""PARS: the update rule by hand, a known quadratic objective, the normaliser, guards,
determinism and device counts, on toy episodes (nothing about grids), run as a trainer runs
them (`ars.pars.Pars` composed with the episodes' batching and sharding,
`jaxgrid.population.evaluator`); a second strategy (plain ES) through the same iteration."""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.sharding import Mesh

import ars.iteration
from ars import normalizer
from ars.es import PlainEs
from ars.iteration import clean_returns, default_mesh, returns_of
from ars.normalizer import RunningStats, initial_carry, normalized_policy
from ars.pars import Pars, ParsConfig, ars_update, init_state
from ars.policies import Policy, PolicySpec
from jaxgrid.population import evaluator

TARGETS = jnp.array([[-0.05, -0.15], [-0.10, -0.02], [-0.18, -0.08], [-0.12, -0.12]])


def quadratic_episode(apply, params, task, carry, scale=1.0):
    """One step: observe the task's target (2,), act, earn −100·scale·|action − target|²
    (`scale`: the iteration's data)."""
    action, carry = apply(params, task, carry, None)
    return {"reward": -100.0 * scale * jnp.sum((action - task) ** 2), "policy_carry": carry}


class ShortfallEpisode:
    """A looped toy episode: each step earns `quadratic_episode`'s reward, and the episode
    ends once its total falls below `floor` or after `steps` steps, so the episodes of a
    batch end at different steps. Runs whole or in two parts (`begin`, then `resume`), as
    `ParsConfig.compact_after` needs."""

    steps, floor = 6, -1.5

    def __call__(self, apply, params, task, carry, scale=1.0):
        return self.result(self.resume(apply, params, task, scale,
                                       self.begin(apply, params, task, carry, scale, 0)))

    def begin(self, apply, params, task, carry, scale, steps):
        loop = (jnp.zeros((), jnp.int32), carry, jnp.zeros(()), jnp.zeros((), bool))
        return self._run(apply, params, task, scale, loop, steps)

    def resume(self, apply, params, task, scale, loop):
        return self._run(apply, params, task, scale, loop, self.steps)

    def _run(self, apply, params, task, scale, loop, until):
        def step(loop):
            k, carry, total, _ = loop
            out = quadratic_episode(apply, params, task, carry, scale)
            total = total + out["reward"]
            return k + 1, out["policy_carry"], total, (total < self.floor) | (k + 1 >= self.steps)

        return jax.lax.while_loop(lambda lp: (lp[0] < until) & ~lp[3], step, loop)

    @staticmethod
    def done(loop):
        return loop[3]

    @staticmethod
    def result(loop):
        return {"reward": loop[2], "policy_carry": loop[1], "steps": loop[0]}


def make_iteration(episode, policy, config, sample=None, mesh=None, seeds=None,
                   strategy=None):
    """The iteration of `config` on toy episodes, composed as `ars.train.make_trainer` composes
    it: `strategy` (default `Pars(config)`) and the episodes' evaluator."""
    mesh = mesh or default_mesh()
    evaluate = evaluator(episode, normalized_policy(policy), initial_carry(policy), mesh,
                         config.task_batch, config.compact_after, config.compact_chunks)
    return ars.iteration.make_iteration(strategy or Pars(config), evaluate,
                                        config.tasks_per_iteration, sample, mesh, seeds,
                                        config.task_returns)


def test_update_equals_the_hand_computed_one():
    rng = np.random.default_rng(0)
    theta, delta = rng.normal(size=5), rng.normal(size=(4, 5))
    r_plus, r_minus = np.array([1.0, 5.0, -2.0, 0.5]), np.array([3.0, -1.0, 4.0, 0.0])
    new, best = ars_update(jnp.asarray(theta), jnp.asarray(delta), jnp.asarray(r_plus),
                           jnp.asarray(r_minus), top=2, step_size=0.3)
    # max(r+, r−) = [3, 5, 4, 0.5]: the top two are directions 1 and 2
    assert sorted(np.asarray(best).tolist()) == [1, 2]
    sigma = np.std([5.0, -2.0, -1.0, 4.0])
    expected = theta + 0.3 / (2 * sigma) * ((5.0 - -1.0) * delta[1] + (-2.0 - 4.0) * delta[2])
    np.testing.assert_allclose(np.asarray(new), expected, rtol=1e-5)


def test_zero_spread_and_non_finite_returns_are_guarded():
    theta, delta = jnp.zeros(3), jnp.ones((2, 3))
    same = jnp.array([2.0, 2.0])
    new, _ = ars_update(theta, delta, same, same, top=2, step_size=1.0)
    assert np.all(np.isfinite(np.asarray(new))) and np.allclose(np.asarray(new), 0.0)
    cleaned = clean_returns(jnp.array([jnp.nan, -5.0, jnp.inf, 3.0, -jnp.inf]))
    assert np.asarray(cleaned).tolist() == [-5.0, -5.0, -5.0, 3.0, -5.0]
    _, best = ars_update(theta, delta, cleaned[:2], cleaned[2:4], top=1, step_size=1.0)
    assert int(best[0]) == 1, "a non-finite return must never rank first"


def test_task_ranks_and_zscores_weigh_every_task_alike():
    """Centred ranks per task (columns), ties sharing their mean rank, then averaged: a task
    whose rewards differ by thousands counts as much as one that differs by units, a task on
    which all are equal adds nothing, and a non-finite reward ranks lowest; z-scores per task
    likewise, by hand."""
    rewards = jnp.array([[-10_000.0, -51.0, -7.0],
                         [-100.0, -50.0, -7.0],
                         [-100.0, -52.0, -7.0],
                         [jnp.nan, -49.0, -7.0]])
    # task 0: nan lowest (0), -10 000 next (1), the two -100 share ranks 2 and 3 (2.5)
    # task 1: -52 < -51 < -50 < -49 (0, 1, 2, 3); task 2: all equal (1.5 each)
    ranks = np.array([[1, 1, 1.5], [2.5, 2, 1.5], [2.5, 0, 1.5], [0, 3, 1.5]]) / 3 - 0.5
    np.testing.assert_allclose(np.asarray(returns_of(rewards, "ranks")), ranks.mean(1),
                               rtol=1e-6)
    # ranks+mean adds the centred rank of each row's mean: -3 352.7, -52.3, -53, nan
    np.testing.assert_allclose(np.asarray(returns_of(rewards, "ranks+mean")),
                               ranks.mean(1) + np.array([1, 3, 2, 0]) / 3 - 0.5, rtol=1e-6)
    mean = np.asarray(returns_of(rewards[:3]))
    np.testing.assert_allclose(mean, [-3352.6667, -52.3333, -53.0], rtol=1e-6)
    assert np.argmax(mean) == 1 and np.argmax(returns_of(rewards[:3], "ranks")) == 1
    # z-scores of the first three: task 0 (-10 000, -100, -100) has mean -3 400, std
    # 4 666.9; task 1 (-51, -50, -52) mean -51, std 0.8165; task 2 adds 0
    spread = np.array([np.std([-10_000.0, -100, -100]), np.std([-51.0, -50, -52])])
    z = np.array([[-6600 / spread[0], 0], [3300 / spread[0], 1 / spread[1]],
                  [3300 / spread[0], -1 / spread[1]]])
    np.testing.assert_allclose(np.asarray(returns_of(rewards[:3], "zscores")), z.sum(1) / 3,
                               rtol=1e-5)
    with pytest.raises(ValueError, match="task_returns = 'median': allowed mean, ranks, "
                                         r"ranks\+mean, zscores"):
        returns_of(rewards, "median")


def test_normaliser_merge_equals_the_pooled_statistics():
    rng = np.random.default_rng(1)
    a, b = rng.normal(2.0, 3.0, size=(50, 4)), rng.normal(-1.0, 0.5, size=(70, 4))
    stats = RunningStats.empty(4)
    for batch in (a, b):
        stats = normalizer.merge(stats, len(batch), batch.sum(0), (batch ** 2).sum(0))
    pooled = np.concatenate([a, b])
    np.testing.assert_allclose(np.asarray(stats.mean), pooled.mean(0), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(stats.std), pooled.std(0), rtol=1e-4)
    constant = normalizer.merge(RunningStats.empty(1), 3, jnp.array([3.0]), jnp.array([3.0]))
    assert float(constant.std[0]) == 1.0, "a constant feature is not scaled up"


def test_the_std_floor_bounds_the_scale_of_a_varying_input_only():
    """floor 0.01: an input of std 0.002 is scaled by 1/0.01, one of std 0.5 by its own, and
    a constant one by 1, as without a floor; the floor survives merges (a static field)."""
    x = np.array([[1.0, 0.0, 7.0], [1.004, 1.0, 7.0]])  # stds 0.002, 0.5, 0
    stats = normalizer.merge(RunningStats.empty(3, floor=0.01), 2, x.sum(0), (x ** 2).sum(0))
    assert stats.floor == 0.01
    np.testing.assert_allclose(np.asarray(stats.std), [0.01, 0.5, 1.0], rtol=1e-3)
    state = init_state(Policy(PolicySpec("linear", 3, 1, ())), ParsConfig(obs_std_floor=0.01))
    assert state.stats.floor == 0.01
    with pytest.raises(ValueError, match=r"obs_std_floor = 0.0: allowed None or > 0"):
        ParsConfig(obs_std_floor=0.0)


@pytest.mark.parametrize("kind, hidden", [("linear", ()), ("fnn", (8, 8)), ("lstm", (8, 4))])
def test_policies_start_at_no_control_and_stay_in_range(kind, hidden):
    policy = Policy(PolicySpec(kind, 3, 2, hidden, -0.2, 0.0))
    obs = jnp.array([0.5, -1.0, 2.0])
    action, _ = policy.apply(policy.initial_theta(), obs, policy.initial_carry())
    assert np.asarray(action).tolist() == [0.0, 0.0]
    theta = jax.random.normal(jax.random.PRNGKey(0), (policy.size,)) * 5
    action, carry = policy.apply(theta, obs, policy.initial_carry())
    assert np.all((np.asarray(action) >= -0.2) & (np.asarray(action) <= 0.0))
    assert jax.tree.structure(carry) == jax.tree.structure(policy.initial_carry())


def test_a_clipped_policy_sees_inputs_beyond_the_clip_as_the_clip(tmp_path):
    """obs_clip = 2: an input of 9 acts as 2, one within ±2 as itself; the clip travels with
    a saved policy; 0 is refused naming the field."""
    from ars.checkpoint import load_policy, save_policy

    clipped, plain = (Policy(PolicySpec("fnn", 3, 2, (8,), -0.2, 0.0, clip))
                      for clip in (2.0, None))
    theta = jax.random.normal(jax.random.PRNGKey(2), (clipped.size,))
    act = lambda policy, obs: np.asarray(
        policy.apply(theta, jnp.array(obs), policy.initial_carry())[0])
    np.testing.assert_array_equal(act(clipped, [0.5, 9.0, -1.0]), act(plain, [0.5, 2.0, -1.0]))
    np.testing.assert_array_equal(act(clipped, [0.5, 1.5, -1.0]), act(plain, [0.5, 1.5, -1.0]))
    assert not np.allclose(act(plain, [0.5, 9.0, -1.0]), act(plain, [0.5, 2.0, -1.0]))
    state = init_state(clipped, ParsConfig())
    save_policy(tmp_path, clipped.spec, state, {})
    assert load_policy(tmp_path)[0].spec.obs_clip == 2.0
    with pytest.raises(ValueError, match=r"obs_clip = 0.0: allowed None or > 0"):
        PolicySpec("fnn", 3, 2, (8,), -0.2, 0.0, 0.0)


def test_relative_inputs_see_the_change_since_the_first_observation(tmp_path):
    """relative_inputs: two episodes whose observations differ by a constant offset (one
    operating point and another, before any fault) give the same actions step by step, and
    the normaliser sums the changes, not the observations; the paper's absolute inputs tell
    them apart. The switch travels with a saved policy."""
    from ars.checkpoint import load_policy, save_policy

    relative, plain = (Policy(PolicySpec("lstm", 3, 2, (8,), -0.2, 0.0, None, rel))
                       for rel in (True, False))
    theta = jax.random.normal(jax.random.PRNGKey(3), (relative.size,)) * 3
    params = (theta, jnp.array([0.1, -0.2, 0.3]), jnp.array([0.5, 2.0, 1.0]))
    steps = jnp.array([[1.0, 0.9, 1.0], [1.0, 0.9, 1.0], [0.7, 0.6, 1.0], [0.8, 0.85, 0.9]])
    offset = jnp.array([-0.02, 0.05, 0.0])

    def play(policy, observations):
        apply, carry, actions = normalized_policy(policy), initial_carry(policy), []
        for obs in observations:
            action, carry = apply(params, obs, carry, None)
            actions.append(np.asarray(action))
        return np.array(actions), carry

    (here, carry), (there, _) = play(relative, steps), play(relative, steps + offset)
    np.testing.assert_allclose(here, there, atol=1e-6)
    _, (count, total, total_sq) = carry
    changes = np.asarray(steps - steps[0])
    assert float(count) == 4
    np.testing.assert_allclose(total, changes.sum(0), atol=1e-6)
    np.testing.assert_allclose(total_sq, (changes ** 2).sum(0), atol=1e-6)
    assert not np.allclose(play(plain, steps)[0], play(plain, steps + offset)[0], atol=1e-4)
    save_policy(tmp_path, relative.spec, init_state(relative, ParsConfig()), {})
    assert load_policy(tmp_path)[0].spec.relative_inputs


@pytest.fixture(scope="module")
def quadratic():
    policy = Policy(PolicySpec("linear", 2, 2, (), -0.2, 0.0))
    config = ParsConfig(directions=8, top=4, step_size=0.2, noise=0.1, decay=0.995,
                        tasks_per_iteration=2, seed=3)
    return policy, config


def _train(policy, config, iterations, mesh=None, episode=quadratic_episode):
    iteration = make_iteration(episode, policy, config, mesh=mesh)
    state, history = init_state(policy, config), []
    for _ in range(iterations):
        state, metrics = iteration(state, TARGETS, 1.0)
        history.append({k: float(v) for k, v in metrics.items()})
    return state, history, iteration


def _objective(policy, state):
    """Mean reward of the unperturbed policy θ over all targets (normalised as in training)."""
    apply, params = normalized_policy(policy), (state.theta, state.stats.mean, state.stats.std)
    rewards = [quadratic_episode(apply, params, t, initial_carry(policy))["reward"]
               for t in TARGETS]
    return float(np.mean(rewards))


def test_ars_improves_a_quadratic_objective(quadratic):
    policy, config = quadratic
    start = _objective(policy, init_state(policy, config))
    state, _, iteration = _train(policy, config, 60)
    end = _objective(policy, state)
    print(f"\nquadratic: reward of θ {start:.3f} -> {end:.3f} (optimum 0)")
    assert end > 0.2 * start, "ARS should remove most of the initial loss"
    assert iteration.compiled._cache_size() == 1, "the iteration compiles once"
    assert int(state.iteration) == 60
    assert float(state.step_size) == pytest.approx(0.2 * 0.995 ** 60, rel=1e-5)
    assert float(state.stats.count) == 60 * 2 * 8 * 2, "every rollout's observation merged"
    for how in ("ranks", "ranks+mean", "zscores"):
        shaped, history, _ = _train(policy, dataclasses.replace(config, task_returns=how), 60)
        print(f"with task {how}: {_objective(policy, shaped):.3f}")
        assert _objective(policy, shaped) > 0.2 * start, f"{how} should remove most too"
        assert history[-1]["reward_mean"] < 0, "metrics stay in reward units"


def test_same_seed_same_theta_and_device_counts_agree(quadratic):
    policy, config = quadratic
    one_a, _, _ = _train(policy, config, 5, Mesh(np.array(jax.devices()[:1]), ("batch",)))
    one_b, _, _ = _train(policy, config, 5, Mesh(np.array(jax.devices()[:1]), ("batch",)))
    two, _, _ = _train(policy, config, 5, Mesh(np.array(jax.devices()[:2]), ("batch",)))
    np.testing.assert_array_equal(np.asarray(one_a.theta), np.asarray(one_b.theta))
    np.testing.assert_allclose(np.asarray(two.theta), np.asarray(one_a.theta), atol=1e-5)
    other, _, _ = _train(policy, ParsConfig(**{**config.__dict__, "seed": 4}), 5)
    assert not np.allclose(np.asarray(other.theta), np.asarray(one_a.theta))


def test_seeds_in_one_program_equal_the_runs_one_by_one(quadratic):
    """3 seeds vmapped into one compiled iteration (a leading seed axis on the state) end
    where 3 separate runs of seeds 3, 4, 5 end, to float32 summation-order tolerance."""
    policy, config = quadratic
    iteration = make_iteration(quadratic_episode, policy, config, seeds=3)
    state = init_state(policy, config, seeds=3)
    for _ in range(5):
        state, metrics = iteration(state, TARGETS, 1.0)
    assert metrics["reward_mean"].shape == (3,)
    for i in range(3):
        alone, history, _ = _train(policy, dataclasses.replace(config, seed=config.seed + i), 5)
        np.testing.assert_allclose(np.asarray(state.theta[i]), np.asarray(alone.theta),
                                   rtol=1e-5, atol=1e-6)
        assert float(metrics["reward_mean"][i]) == pytest.approx(history[-1]["reward_mean"],
                                                                 rel=1e-5)
    assert not np.allclose(np.asarray(state.theta[0]), np.asarray(state.theta[1]))


def test_tasks_in_batches_equal_all_tasks_at_once(quadratic):
    """task_batch runs the m tasks in batches one after another (lax.map): the same θ, to
    float32 rounding. (Not bitwise: the batch is every array's minor axis (`vmap_minor`),
    so batches of 1 and of m compile to differently vectorised loops, which may round
    differently; five iterations of θ = O(1) stay within 1e-5.)"""
    policy, config = quadratic
    together, _, _ = _train(policy, config, 5)
    batched, _, _ = _train(policy, dataclasses.replace(config, task_batch=1), 5)
    np.testing.assert_allclose(np.asarray(batched.theta), np.asarray(together.theta),
                               rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("task_batch, chunks", [(None, 3), (1, 4), (None, 1)])
def test_regrouped_episodes_equal_whole_ones(quadratic, task_batch, chunks):
    """compact_after: the episodes still running after the first step continue regrouped in
    chunks (3: ⌈16/3⌉ = 6 lanes, the last chunk padded; 1: all lanes) or, with one task per
    batch, sharing their task: the same θ and the same steps as whole episodes, to float32
    rounding (the chunks are batches of other sizes). Episodes end at 1 to 6 steps."""
    policy, config = quadratic
    config = dataclasses.replace(config, task_batch=task_batch, noise=0.3)
    whole, whole_log, _ = _train(policy, config, 4, episode=ShortfallEpisode())
    split, split_log, _ = _train(policy, dataclasses.replace(
        config, compact_after=1, compact_chunks=chunks), 4, episode=ShortfallEpisode())
    np.testing.assert_allclose(np.asarray(split.theta), np.asarray(whole.theta), rtol=1e-5,
                               atol=1e-6)
    assert [row["env_steps"] for row in split_log] == [row["env_steps"] for row in whole_log]
    steps = [row["env_steps"] / row["rollouts"] for row in whole_log]
    assert 1 < min(steps) and max(steps) < ShortfallEpisode.steps, \
        f"mean steps per episode {steps}: the episodes must end at different steps"


def test_regrouped_episodes_under_the_seed_vmap(quadratic):
    """With seeds vmapped into one program, each seed's chunk count differs (the chunk loop
    runs the largest, the others' extra chunks change nothing): θ as whole episodes."""
    policy, config = quadratic
    config = dataclasses.replace(config, noise=0.3)
    thetas = []
    for compact in (None, 1):
        regrouped = dataclasses.replace(config, compact_after=compact, compact_chunks=3)
        iteration = make_iteration(ShortfallEpisode(), policy, regrouped, seeds=2)
        state = init_state(policy, regrouped, seeds=2)
        for _ in range(3):
            state, _ = iteration(state, TARGETS, 1.0)
        thetas.append(np.asarray(state.theta))
    np.testing.assert_allclose(thetas[1], thetas[0], rtol=1e-5, atol=1e-6)


def test_bad_hyper_parameters_are_named(quadratic):
    policy, config = quadratic
    with pytest.raises(ValueError, match=r"top = 9: allowed in \[1, directions = 8\]"):
        ParsConfig(directions=8, top=9)
    with pytest.raises(ValueError, match="decay = 1.5"):
        ParsConfig(decay=1.5)
    with pytest.raises(ValueError, match="task_returns = 'median': allowed mean, ranks, "
                                         r"ranks\+mean, zscores"):
        ParsConfig(task_returns="median")
    with pytest.raises(ValueError, match="compact_after = 0: allowed None or >= 1"):
        ParsConfig(compact_after=0)
    with pytest.raises(ValueError, match=r"compact_after = 2: the episode must run in two "
                                         r"parts \(begin, resume, done, result"):
        make_iteration(quadratic_episode, policy, ParsConfig(compact_after=2))
    iteration = make_iteration(quadratic_episode, policy, ParsConfig(tasks_per_iteration=5))
    with pytest.raises(ValueError, match="tasks_per_iteration = 5: only 4 tasks"):
        iteration(init_state(policy, config), TARGETS, 1.0)
    with pytest.raises(ValueError, match=r"6 parameter vectors \(the strategy's population\) "
                                         "do not split over 4 devices"):
        make_iteration(quadratic_episode, policy, ParsConfig(directions=3, top=1),
                       mesh=Mesh(np.array(jax.devices()[:1] * 4).reshape(4), ("batch",)))


def test_tasks_data_and_sampler_are_arguments(quadratic):
    """New tasks or data of the same shapes reuse the compilation; a sampler picks the tasks."""
    policy, config = quadratic
    picked = []

    def sample(key):
        return jax.random.randint(key, (config.tasks_per_iteration,), 0, 2)

    def episode(apply, params, task, carry, scale):
        return quadratic_episode(apply, params, task, carry, scale)

    iteration = make_iteration(episode, policy, config, sample)
    state = init_state(policy, config)
    for targets, scale in ((TARGETS, 1.0), (TARGETS[::-1], 1.0), (TARGETS, 0.0)):
        _, metrics = iteration(state, targets, scale)
        picked.append(float(metrics["reward_mean"]))
    assert iteration.compiled._cache_size() == 1
    assert picked[2] == 0.0 and picked[0] < 0.0, "the data scales the reward"
    assert picked[0] != picked[1], "the sampler indexes the tasks given"


def test_env_steps_count_the_steps_each_episode_reports(quadratic):
    """An episode that reports its steps (a failed one stops early) is counted as it says:
    tasks of 3 and 5 steps, both drawn, 2N = 16 rollouts each."""
    policy, config = quadratic

    def episode(apply, params, task, carry, scale):
        out = quadratic_episode(apply, params, task, carry, scale)
        return {**out, "steps": jnp.where(task[0] < -0.07, 5, 3)}

    iteration = make_iteration(episode, policy, config)
    _, metrics = iteration(init_state(policy, config), TARGETS[:2], 1.0)
    assert int(metrics["env_steps"]) == 16 * (3 + 5)
    _, metrics = make_iteration(quadratic_episode, policy, config)(
        init_state(policy, config), TARGETS, 1.0)
    assert "env_steps" not in metrics, "an episode without steps reports none"


def test_a_second_strategy_is_a_new_file_run_by_the_same_iteration(quadratic):
    """Plain ES (`ars.es.PlainEs`, a file of its own: nothing of the iteration, the problem
    or PARS edited for it) composed with the same evaluator removes most of the quadratic's
    initial loss, as PARS does (`test_ars_improves_a_quadratic_objective`), and keeps α."""
    policy, config = quadratic
    run = make_iteration(quadratic_episode, policy, config, strategy=PlainEs(pairs=8))
    state = init_state(policy, config)
    start = _objective(policy, state)
    for _ in range(60):
        state, metrics = run(state, TARGETS, 1.0)
    end = _objective(policy, state)
    print(f"\nplain ES on the quadratic: reward of θ {start:.3f} -> {end:.3f} (optimum 0)")
    assert end > 0.2 * start, "plain ES should remove most of the initial loss"
    assert float(state.step_size) == pytest.approx(config.step_size)
    assert int(metrics["rollouts"]) == 16 * config.tasks_per_iteration
