"""The load-shedding environment: each reward term by hand, then whole steps and episodes
(`jaxgrid.episode`).

Episodes run on the built-in ieee39_fidvr study, shortened to 6 s (the fault at 1 s and the
4 s recovery check still fit), with one compiled rollout shared by the tests. The grid model
is an argument of every call.
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrid.env import (EnvParams, envelope_deviation, invalid_requests, normal_requests,
                         prefault_requests, recovery_failed, shed_power)
from jaxgrid.recovery import mask_allows, normal_operation, supervision_allows
from jaxgrid.episode import play_tasks
from jaxgrid.simulate import FaultEvent, make_task, stack_tasks
from jaxgrid.study import builtin


@pytest.mark.parametrize("t_after, expected", [
    (-0.1, 0.0),   # before clearing: no envelope
    (0.2, 0.0),    # 0.7 p.u.: all above
    (0.33, 0.0),   # (0, 0.33] is still 0.7
    (0.4, -0.05),  # 0.8: 0.75 is 0.05 short
    (1.0, -0.20),  # 0.9: 0.15 + 0.05 short
    (2.0, -0.30),  # 0.95: 0.20 + 0.10 short, 0.96 fine
])
def test_envelope_deviation_by_hand(t_after, expected):
    vm = jnp.array([0.75, 0.85, 0.96])
    assert float(envelope_deviation(vm, t_after)) == pytest.approx(expected, abs=1e-6)


def test_shed_invalid_and_prefault_terms_by_hand():
    request = jnp.array([0.2, 0.0, 0.1])
    assert float(shed_power(jnp.array([0.2, 0.1, 0.0]), jnp.array([5.0, 3.0, 2.0]))) == \
        pytest.approx(1.3)
    assert int(invalid_requests(request, jnp.array([0.0, 0.0, 0.5]))) == 1
    assert int(prefault_requests(request, 0.5, 1.0)) == 2
    assert int(prefault_requests(request, 1.5, 1.0)) == 0


@pytest.mark.parametrize("t_after, normal, allowed", [
    (-0.5, [False, False, False], [False, False, False]),  # before clearing: never normal
    (0.1, [True, True, False], [False, False, False]),     # 0.8 p.u., but the 0.15-s hold
    (0.2, [True, True, False], [False, False, True]),      # 0.8 p.u. over (0, 0.33]
    (0.4, [True, False, False], [False, True, True]),      # 0.9 p.u. over (0.33, 0.5]
    (0.6, [False, False, False], [True, True, True]),      # 0.95 p.u. after 0.5 s
])
def test_normal_operation_and_the_mask_by_hand(t_after, normal, allowed):
    """HADREC's thresholds (GridPackPowerDynSimEnvDef_v10.py): a bus at 0.93, 0.85, 0.75 p.u.
    is in normal operation while it is at or above 0.8/0.9/0.95 p.u. (to 0.33/0.5 s/after),
    and the mask lets it shed when it is not, from 0.15 s after clearing."""
    vm = np.array([0.93, 0.85, 0.75])
    assert normal_operation(vm, t_after).tolist() == normal
    assert np.asarray(normal_operation(jnp.asarray(vm), t_after, jnp)).tolist() == normal
    assert mask_allows(vm, t_after).tolist() == allowed
    # undervoltage supervision at 0.9 p.u.: the 0.93-p.u. bus held after clearing only
    assert supervision_allows(vm, t_after, 0.9).tolist() == [t_after <= 0, True, True]
    request = jnp.array([0.2, 0.0, 0.1])
    assert int(normal_requests(request, jnp.asarray(vm), t_after)) == normal[0] + normal[2]


def test_recovery_check_by_hand():
    params = EnvParams()
    vm = jnp.array([0.94, 0.96])
    both = jnp.array([True, True])
    assert bool(recovery_failed(vm, both, 4.1, params))
    assert not bool(recovery_failed(vm, both, 3.9, params)), "too early to judge"
    assert not bool(recovery_failed(vm, jnp.array([False, True]), 4.1, params)), \
        "a bus that started below the level is not checked"


@pytest.fixture(scope="module")
def study(ieee39):
    return ieee39


@pytest.fixture(scope="module")
def env(study):
    return study.env(episode=6.0)


@pytest.fixture(scope="module")
def grid(study):
    return study.point(0)


@pytest.fixture(scope="module")
def tasks(grid):
    """[no fault, bus-4 0.02 s (recovers), bus-4 0.08 s (FIDVR)]."""
    faults = [None, FaultEvent(4, 1.0, 0.02), FaultEvent(4, 1.0, 0.08)]
    return [make_task(grid, f) for f in faults]


def test_pre_fault_shedding_step_by_hand(env, grid, tasks):
    params = EnvParams()
    step = jax.jit(env.step)
    obs, state = env.reset(None, tasks[2], params, grid)
    assert obs.shape == (env.obs_size,)
    action = jnp.array([-0.2, 0.0, 0.0])  # shed 20 % at 504, before the fault
    p0 = float(grid.load_p0[env.action_slots[0]])
    obs, state, reward, done, info = step(state, action, params, grid)
    assert float(reward) == pytest.approx(-150.0 * 0.2 * p0 - 100.0, rel=1e-5)
    assert float(obs[-3]) == pytest.approx(0.8) and not bool(done)
    empty = state.replace(grid=state.grid.replace(
        load_left=state.grid.load_left.at[env.action_slots[0]].set(0.0)))
    _, _, reward, _, info = step(empty, action, params, grid)
    assert float(reward) == pytest.approx(-3.0 - 100.0, rel=1e-6), "invalid + pre-fault only"
    assert float(info["shed_pu"]) == 0.0


def test_requests_within_the_action_deadband_are_dropped(study, grid, tasks):
    """action_deadband = 0.01 (HADREC's GridPACK environment): a request of 0.5 % is neither
    applied nor charged (shed or pre-fault), one of 2 % is both."""
    env = study.env(action_deadband=0.01)
    params = EnvParams()
    _, state = env.reset(None, tasks[2], params, grid)
    _, state, reward, _, info = jax.jit(env.step)(state, jnp.array([-0.005, -0.02, 0.0]),
                                                  params, grid)
    p0 = float(grid.load_p0[env.action_slots[1]])
    assert float(info["shed_pu"]) == pytest.approx(0.02 * p0, rel=1e-5)
    assert float(reward) == pytest.approx(-150.0 * 0.02 * p0 - 100.0, rel=1e-5)
    assert np.asarray(state.grid.load_left[env.action_slots]) == pytest.approx([1.0, 0.98, 1.0])


def test_shed_limit_clips_requests_and_charges_them_past_it(study, grid, tasks):
    """shed_limit = 0.6 (the three UVLS stages' sum): at buses with 0.5 and 0.4 of their
    load left, 20 % requests shed 0.1 and nothing (charged as an invalid request, as at an
    empty bus), the bus with all its load sheds 0.2; a bad limit is refused by name."""
    env = study.env(shed_limit=0.6)
    params = EnvParams()
    _, state = env.reset(None, tasks[2], params, grid)
    left = jnp.asarray(state.grid.load_left).at[env.action_slots[:2]].set(jnp.array([0.5, 0.4]))
    state = state.replace(grid=state.grid.replace(load_left=left))
    _, state, reward, _, info = jax.jit(env.step)(state, jnp.full(3, -0.2), params, grid)
    p0 = np.asarray(grid.load_p0)[env.action_slots]
    assert np.asarray(state.grid.load_left[env.action_slots]) == pytest.approx([0.4, 0.4, 0.8])
    assert float(info["shed_pu"]) == pytest.approx(0.1 * p0[0] + 0.2 * p0[2], rel=1e-5)
    assert float(reward) == pytest.approx(-150.0 * float(info["shed_pu"]) - 3.0 - 3 * 100.0,
                                          rel=1e-5), "shed, one invalid, 3 pre-fault requests"
    with pytest.raises(ValueError, match="shed_limit"):
        study.env(shed_limit=0.0)


def test_the_mask_drops_requests_in_normal_operation_and_c_normal_charges_them(study, grid,
                                                                                tasks):
    """With action_mask "hadrec" a request at a bus in normal operation is dropped (nothing
    shed, nothing charged for shedding), one at a low bus is applied, and c_normal charges
    each request in normal operation whether the mask drops it or not; "undervoltage" drops
    the request at the bus at the 0.95-p.u. recovery level alike, but not in the hold. The
    agent step at 1.3 s is 0.22 s after the bus-4 0.08-s fault clears: the 0.8-p.u. level,
    past the hold; the bus voltages of the newest observation are set by hand (0.95, 0.7,
    0.95 p.u.). A policy that masks its own requests sheds, where the environment has no
    mask, what the masked environment sheds, and under the mask is charged no c_normal."""
    request = jnp.array([-0.2, -0.2, 0.0])
    p0 = np.asarray(grid.load_p0)
    out, steps = {}, {}
    for mask in ("none", "hadrec", "undervoltage"):
        env = study.env(action_mask=mask)
        steps[mask] = step = jax.jit(env.step)
        _, start = env.reset(None, tasks[2], EnvParams(), grid)
        state = start.replace(step=jnp.asarray(13, jnp.int32),
                              action_vm=jnp.array([0.95, 0.7, 0.95]))
        for c_normal in (0.0, 3.0):
            _, new, reward, _, info = step(state, request, EnvParams(c_normal=c_normal), grid)
            out[mask, c_normal] = (float(reward), float(info["shed_pu"]),
                                   np.asarray(new.grid.load_left[env.action_slots]))
    shed_507 = 0.2 * p0[study.env().action_slots[1]]
    shed_both = shed_507 + 0.2 * p0[study.env().action_slots[0]]
    for mask in ("hadrec", "undervoltage"):
        assert out[mask, 0.0][1] == pytest.approx(shed_507, rel=1e-6)
        assert out[mask, 0.0][2] == pytest.approx([1.0, 0.8, 1.0])
    assert out["none", 0.0][1] == pytest.approx(shed_both, rel=1e-6)
    assert out["none", 0.0][2] == pytest.approx([0.8, 0.8, 1.0])
    for mask in ("none", "hadrec"):  # one request (at 504) in normal operation: c_normal once
        assert out[mask, 0.0][0] - out[mask, 3.0][0] == pytest.approx(3.0, abs=1e-3)
    held = start.replace(step=jnp.asarray(11, jnp.int32), action_vm=jnp.full(3, 0.5))
    _, new, _, _, info = steps["hadrec"](held, request, EnvParams(c_normal=3.0), grid)
    # 0.02 s after clearing: held
    assert float(info["shed_pu"]) == 0.0
    _, _, _, _, info = steps["undervoltage"](held, request, EnvParams(c_normal=3.0), grid)
    assert float(info["shed_pu"]) == pytest.approx(shed_both, rel=1e-6)  # below 0.95: applied
    assert np.asarray(new.action_vm).shape == (3,)
    # the lowest action-bus voltage from the 0.15-s hold on (what an arming level reads):
    # none at the reset nor 0.12 s after clearing, the newest observation's 0.32 s after
    assert float(start.lowest_action_vm) == float(new.lowest_action_vm) == np.inf
    _, later, _, _, _ = steps["none"](state, jnp.zeros(3), EnvParams(), grid)
    assert float(later.lowest_action_vm) == float(jnp.min(later.action_vm)) < 1.0
    # a policy trained under a mask, run where the environment has none, masks its own
    # requests (`jaxgrid.episode.masked`): the environment without a mask then sheds
    # what the masked one does, at both states
    from jaxgrid.episode import ControlInputs, masked

    for mask in ("hadrec", "undervoltage"):
        own = masked(lambda params, obs, carry, inputs: (request, carry), mask, study.env())
        for at in (state, held):
            inputs = ControlInputs(at, grid, EnvParams(), at.step)
            action, _ = own(None, None, None, inputs)
            _, by_policy, _, _, policy_info = steps["none"](at, action, EnvParams(), grid)
            _, by_env, _, _, env_info = steps[mask](at, request, EnvParams(), grid)
            assert float(policy_info["shed_pu"]) == float(env_info["shed_pu"]), (mask, at.step)
            np.testing.assert_array_equal(by_policy.grid.load_left, by_env.grid.load_left)
        # under its own mask (--self-mask) it makes no request in normal operation, so
        # c_normal charges nothing: the reward the masked environment gives without c_normal
        action, _ = own(None, None, None, ControlInputs(state, grid, EnvParams(), state.step))
        _, _, reward, _, _ = steps[mask](state, action, EnvParams(c_normal=3.0), grid)
        assert float(reward) == pytest.approx(out[mask, 0.0][0], rel=1e-6), mask
    # with an arming level of 0.85 p.u. (--arming-level) it asks nothing until an action bus
    # has been observed below 0.85 p.u. from the hold on: the lowest, none before the hold
    # (inf), 0.86 p.u. or 0.84 p.u.
    armed = masked(lambda params, obs, carry, inputs: (request, carry), "hadrec",
                   study.env(), 0.85)
    for lowest, expected in ((np.inf, 0.0), (0.86, 0.0), (0.84, shed_507)):
        at = state.replace(lowest_action_vm=jnp.asarray(lowest))
        action, _ = armed(None, None, None, ControlInputs(at, grid, EnvParams(), at.step))
        _, _, _, _, info = steps["none"](at, action, EnvParams(), grid)
        assert float(info["shed_pu"]) == pytest.approx(expected, rel=1e-6), lowest
    # armed late (--arming-late) as well, never below 0.85 at an action bus: while a bus of
    # the recovery check is below the recovery level that long after clearing (this state
    # 0.22 s after it), not for a bus outside the check nor before that time
    n_observed = len(study.env().observed)
    low = state.history.at[-1, :n_observed].set(1.0).at[-1, 1].set(0.5)
    for late, check, expected in ((0.2, True, shed_507), (0.3, True, 0.0), (0.2, False, 0.0)):
        late_armed = masked(lambda params, obs, carry, inputs: (request, carry), "hadrec",
                            study.env(), 0.85, late)
        at = state.replace(history=low, recovery_check=state.recovery_check.at[1].set(check))
        action, _ = late_armed(None, None, None, ControlInputs(at, grid, EnvParams(), at.step))
        _, _, _, _, info = steps["none"](at, action, EnvParams(), grid)
        assert float(info["shed_pu"]) == pytest.approx(expected, rel=1e-6), (late, check)
    with pytest.raises(ValueError, match=r"--arming-late = 3.0: needs an arming level"):
        masked(lambda *a: a, "hadrec", study.env(), None, 3.0)
    with pytest.raises(ValueError, match=r"--arming-late = 0: allowed 0 < s < 60"):
        masked(lambda *a: a, "hadrec", study.env(), 0.85, 0)


def test_observations_every_obs_interval_end_with_the_agent_step_s_own(study, grid, tasks):
    """obs_interval = 0.02 s (HADREC's GridPACK environment): a 0.1-s agent step appends 5
    observations to the stacked history, the last the one-per-step observation (the same
    simulation steps, run in five parts), the others the fault's course within the step."""
    params = EnvParams()
    zero = jnp.zeros(3)
    stepped = []
    for env in (study.env(history=10), study.env(history=10, obs_interval=0.02)):
        _, state = env.reset(None, tasks[2], params, grid)
        state = state.replace(step=jnp.asarray(10, jnp.int32))  # 1.0-1.1 s: the fault 1.0-1.08
        stepped.append(jax.jit(lambda s, g, env=env: env.step(s, zero, params, g))(state, grid))
    (_, plain, reward, _, _), (obs, sampled, sampled_reward, _, _) = stepped
    assert sampled.history.shape == (10, 11) and obs.shape == (110,)
    np.testing.assert_allclose(sampled.history[-1], plain.history[-1], atol=1e-5)
    np.testing.assert_array_equal(sampled.history[:5], plain.history[:5])  # reset's, copied
    bus4 = np.asarray(sampled.history[5:, 0])  # at 1.02, 1.04, 1.06 s, cleared at 1.08, 1.1
    assert (bus4[:3] < 0.5).all() and (bus4[3:] > 0.5).all(), bus4
    assert float(sampled_reward) == pytest.approx(float(reward), abs=1e-3)
    with pytest.raises(ValueError, match=r"agent_dt = 0.1: must be a whole number \(>= 1\) "
                                         r"of observation intervals obs_interval = 0.03 s"):
        study.env(obs_interval=0.03)


def zero_policy(params, obs, carry, inputs):
    return jnp.zeros(3), carry


def shed_after_fault(params, obs, carry, inputs):
    """Shed 20 % at every action bus on the first step after 1.1 s, once (carry: step count)."""
    return jnp.where(carry == 11, -0.2, 0.0) * jnp.ones(3), carry + 1


@pytest.fixture(scope="module")
def episodes(env, grid, tasks):
    run = jax.jit(functools.partial(play_tasks, env), static_argnums=0)
    batch = stack_tasks(tasks)
    return {name: run(policy, None, batch, EnvParams(), grid, jnp.zeros((3,), jnp.int32))
            for name, policy in (("none", zero_policy), ("shed", shed_after_fault))}, run


def test_uncontrolled_fidvr_fails_recovery_mild_fault_does_not(episodes):
    out = episodes[0]["none"]
    print("\nrewards without control:", np.asarray(out["reward"]).round(1))
    assert np.asarray(out["recovered"]).tolist() == [True, True, False]
    assert float(out["reward"][0]) == pytest.approx(0.0, abs=1e-6), "nothing to pay at rest"
    assert float(out["reward"][2]) <= -1000.0, "the failed episode earns -M"
    assert int(out["steps"][2]) < int(out["steps"][0]) == 60, "failure ends the episode"


def test_shedding_policy_is_charged_for_the_load(episodes, env, grid):
    out = episodes[0]["shed"]
    expected = 0.2 * float(np.sum(np.asarray(grid.load_p0)[env.action_slots]))
    assert np.asarray(out["shed_pu"]) == pytest.approx([expected] * 3, rel=1e-5)


def test_vmap_equals_one_at_a_time(episodes, grid, tasks):
    batched, run = episodes
    for k, task in enumerate(tasks):
        one = run(shed_after_fault, None, stack_tasks([task]), EnvParams(), grid,
                  jnp.zeros((1, 3), jnp.int32)[0])
        for key in ("reward", "shed_pu", "steps"):
            assert float(one[key][0]) == pytest.approx(float(batched["shed"][key][k]),
                                                       rel=1e-5, abs=1e-4), key


def test_buses_below_the_recovery_level_before_the_fault_are_not_checked(env, grid):
    params = EnvParams()
    assert env.unchecked_buses(params, grid) == ()  # the built-in 39-bus case starts >= 0.984
    strict = EnvParams(recovery_level=0.995)  # above 507 (0.994) and 508 (0.990) at rest
    _, state = env.reset(None, make_task(grid, None), strict, grid)
    assert env.unchecked_buses(strict, grid) == (507, 508)
    expected = [b not in (507, 508) for b in env.config.observed_buses]
    assert np.asarray(state.recovery_check).tolist() == expected


def test_recovery_buses_and_action_status_switches(study, grid):
    """recovery_buses narrows the check; include_action_status off drops the load fractions
    (PNNL includeActionStatusInObservations) from the observation."""
    env = study.env(recovery_buses=(4, 504), include_action_status=False)
    obs, state = env.reset(None, make_task(grid, None), EnvParams(), grid)
    assert obs.shape == (8,) and env.obs_size == 8
    assert np.asarray(state.recovery_check).tolist() == [True, True] + [False] * 6
    with pytest.raises(ValueError, match=r"recovery_buses = \[99\]: buses \[99\] are not "
                                         "observed buses"):
        study.env(recovery_buses=(99,))


def test_study_params_per_built_in_case(study):
    assert study.params == EnvParams()
    assert builtin("ieee300_fidvr").params == EnvParams(c_voltage=30.0,
                                                        unstable_penalty=10000.0)


def test_a_diverging_episode_is_flagged_within_one_agent_step(episodes, grid, tasks):
    """A NaN fault impedance poisons the network term (0·NaN) from the first integration
    step on. The divergence check runs once per agent step: that episode ends on its first
    agent step with −M, flagged; the other episode of the batch is unchanged."""
    batched, run = episodes
    poisoned = make_task(grid, FaultEvent(4, 1.0, 0.08, x=float("nan")))
    out = run(zero_policy, None, stack_tasks([tasks[1], poisoned]), EnvParams(), grid,
              jnp.zeros((2,), jnp.int32))
    assert np.asarray(out["diverged"]).tolist() == [False, True]
    assert int(out["steps"][1]) == 1, "the agent step [0, 0.1) s ends it"
    assert not bool(out["recovered"][1]) and float(out["reward"][1]) <= -1000.0
    assert float(out["reward"][0]) == float(batched["none"]["reward"][1])


class ShedAtStep:
    """A planner-style controller (`plans`: its episodes run in a scan) that sheds 20 % at
    every action bus at agent step 11, read from `inputs` (the step index and the state
    before the action), not from its carry (a step count, as `shed_after_fault`'s)."""

    plans = True

    def __call__(self, params, obs, carry, inputs):
        now = (inputs.step == 11) & (inputs.state.step == inputs.step)
        return jnp.where(now, -0.2, 0.0) * jnp.ones(3), carry + 1


def test_a_policy_s_stopping_loop_equals_a_planner_s_full_scan(episodes, env, grid, tasks):
    """Without `trace` a policy's episode loop stops once every episode of the batch is done;
    with it, or for a planner, the scan runs all steps. Both are called controller(params,
    obs, carry, inputs): the planner, reading `inputs`, gives the episodes of the policy,
    which ignores them. The results are the same (to float32 rounding: the two loops are
    compiled apart; here they agree bitwise)."""
    batched, _ = episodes
    traced = jax.jit(functools.partial(play_tasks, env), static_argnums=(0, 6))(
        ShedAtStep(), None, stack_tasks(tasks), EnvParams(), grid,
        jnp.zeros((3,), jnp.int32), True)
    for key in ("steps", "recovered", "policy_carry"):
        np.testing.assert_array_equal(np.asarray(traced[key]), np.asarray(batched["shed"][key]))
    for key in ("reward", "shed_pu"):
        np.testing.assert_allclose(np.asarray(traced[key]), np.asarray(batched["shed"][key]),
                                   rtol=1e-6, err_msg=key)


def test_coarse_step_is_used_outside_the_fault_window(study, tasks):
    """With coarse_dt, an agent step overlapping [fault start, clearing + fine_window) runs
    at dt, every other one at coarse_dt."""
    env = study.env(episode=6.0, coarse_dt=0.02, fine_window=1.0)
    fault = tasks[2]  # 1.0-1.08 s: fine from 1.0 s to 2.08 s
    solver, agent_dt = env.config.solver, env.config.agent_dt
    assert solver.coarse().steps(agent_dt) == 5
    for t, fine in ((0.0, False), (0.9, False), (1.0, True), (2.0, True), (2.1, False)):
        window = solver.in_fault_window(jnp.asarray(t, jnp.float32), agent_dt, fault)
        assert bool(window) == fine, t


def test_a_finished_episode_takes_no_coarse_or_fine_steps(study, grid, tasks):
    """With coarse_dt, a state already done stays where it is: vmapped, the step loops run as
    long as their longest member, so a finished episode must not keep them running."""
    env = study.env(episode=6.0, coarse_dt=0.02, fine_window=1.0)
    params = EnvParams()
    _, state = env.reset(None, tasks[2], params, grid)
    state = state.replace(step=jnp.asarray(10, jnp.int32))  # 1.0 s: inside the fault window
    step = jax.jit(lambda s, g: env.step(s, jnp.zeros(len(env.action_slots)), params, g)[1])
    for done in (False, True):
        new = step(state.replace(done=jnp.asarray(done)), grid)
        moved = max(float(jnp.max(jnp.abs(a - b))) for a, b in
                    zip(jax.tree.leaves(new.grid.integrated()),
                        jax.tree.leaves(state.grid.integrated())))
        assert (moved == 0.0) == done, (done, moved)


@pytest.mark.parametrize("changes, message", [
    ({"coarse_dt": 0.001}, r"coarse_dt = 0.001: must lie in \[0.002, 0.05\] s"),
    ({"coarse_dt": 0.03}, r"agent_dt = 0.1: must be a whole number \(>= 1\) of simulation "
                          r"steps coarse_dt = 0.03 s"),
    ({"coarse_dt": 0.02, "fine_window": -1.0}, r"fine_window = -1.0: must lie in \[0, 3600\]"),
])
def test_coarse_step_values_are_checked(env, changes, message):
    with pytest.raises(ValueError, match=message):
        env.with_config(**changes)


def test_coarse_step_keeps_the_verdicts_and_rewards(episodes, study, grid, tasks):
    """The same three episodes with 10-ms steps outside the fault window: the same recovery
    verdicts, and rewards within 2 % (the envelope deviation of the FIDVR episode sums
    voltage errors of a few 1e-3 p.u., `experiments.diagnostics.step_accuracy`)."""
    fine = episodes[0]["shed"]
    env = study.env(episode=6.0, coarse_dt=0.01, fine_window=1.0)
    coarse = jax.jit(functools.partial(play_tasks, env), static_argnums=0)(
        shed_after_fault, None, stack_tasks(tasks), EnvParams(), grid,
        jnp.zeros((3,), jnp.int32))
    print("\nrewards, fine and coarse:", np.asarray(fine["reward"]).round(2),
          np.asarray(coarse["reward"]).round(2))
    np.testing.assert_array_equal(np.asarray(coarse["recovered"]), np.asarray(fine["recovered"]))
    np.testing.assert_allclose(np.asarray(coarse["reward"]), np.asarray(fine["reward"]),
                               rtol=0.02, atol=0.5)


def test_a_float32_policy_state_runs_in_a_float64_study(study):
    """A saved policy's LSTM state is float32; in a float64 study (`[compile] precision`) its
    update is promoted to float64, and the episode loop must keep the state's dtype."""
    from jaxgrid.problem import play_specs
    from jaxgrid.study.build import rebuild
    from jaxgrid.tasks import TaskSpec

    study64 = rebuild(study, precision="float64")
    env = study64.env(episode=0.3)
    n_action = len(env.action_slots)

    def apply(params, obs, carry, inputs):  # counts the observations' sum in its state
        return jnp.zeros(n_action, obs.dtype), carry + jnp.sum(obs)

    _, out = play_specs(study64, env, apply, None, [TaskSpec(4, 0.0)],
                           jnp.zeros((), jnp.float32))
    assert out["policy_carry"].dtype == np.float32
    assert np.isfinite(out["policy_carry"]).all() and out["policy_carry"][0] != 0.0
    assert out["steps"][0] == 3 and out["recovered"][0]
