"""The MPC baseline: its gradient against central finite differences on a smooth case, one
decision against "no shedding", the stall surrogate leaving trajectories unchanged, and the
option parser.

The gradient check runs the built-in 39-bus study in float64, through the MPC's own
prediction model (10-ms steps, `MpcOptions.dt`) from a state the 2-ms plant reached (central
differences with h = 1e-4 then carry ~h² ≈ 1e-8 relative truncation error and ~1e-12/h
round-off, so 1e-5 relative is a safe bound); the decision runs it in float32, as the
evaluation does.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from baselines.mpc import (MpcOptions, MpcParams, decide, horizon_return, mpc_controller,
                           parse_options, surrogate_model)
from jaxgrid.study import rebuild
from jaxgrid.tasks import TaskSpec

AGENT_STEPS_TO = 13  # decisions at t = 1.3 s: the fault (1.0 s) is on or cleared


def state_at(study, env, spec: TaskSpec, steps: int):
    """(env state after `steps` agent steps without shedding, grid model (jnp arrays))."""
    grid = jax.tree.map(jnp.asarray, study.point(spec.operating_point))
    task = jax.tree.map(lambda a: a[0], study.batch([spec]).task)
    return jax.jit(lambda t: env.state_after(t, study.params, grid, steps))(task), grid


@pytest.fixture(scope="module")
def study32(ieee39):
    return ieee39


def test_gradient_matches_central_differences_without_stall(ieee39):
    with jax.enable_x64(True):
        study = rebuild(ieee39, precision="float64")
        env = study.env()
        # a remote fault through 0.05 p.u.: no motor stalls, every switch stays put
        spec = TaskSpec(fault_bus=29, fault_duration=0.08, fault_start=1.0, operating_point=0,
                        fault_r=0.0, fault_x=0.05)
        state, grid = state_at(study, env, spec, 11)
        model = env.with_config(dt=MpcOptions().dt)  # the MPC's own prediction step, 10 ms
        plan = jnp.full((5, len(env.action_slots)), 0.05)  # inside (0, 0.2): smooth there
        # one program for the gradient and the differences' values (one compile, not two)
        value_and_grad = jax.jit(jax.value_and_grad(lambda p: horizon_return(
            model, p, state, study.params, grid)))
        grad = np.asarray(value_and_grad(plan)[1])
        h = 1e-4
        for k, j in [(0, 0), (0, 2), (2, 1), (4, 0)]:
            e = jnp.zeros_like(plan).at[k, j].set(h)
            central = (float(value_and_grad(plan + e)[0])
                       - float(value_and_grad(plan - e)[0])) / (2 * h)
            assert grad[k, j] == pytest.approx(central, rel=1e-5, abs=1e-6), (k, j)
        assert np.abs(grad).max() > 1.0, "the voltage benefit of shedding shows in the gradient"
        flags = state.grid.load_flags[0]
        assert np.all(np.asarray(flags["run_a"]) == 1.0), "precondition: no motor stalled"


@pytest.fixture(scope="module")
def stalled_case(study32):
    """A bolted 0.1 s fault at bus 4 next to a motor bus: the motors stall (FIDVR)."""
    env = study32.env()
    spec = TaskSpec(fault_bus=4, fault_duration=0.1, fault_start=1.0, operating_point=0,
                    fault_r=0.0, fault_x=1e-4)
    state, grid = state_at(study32, env, spec, AGENT_STEPS_TO)
    return env, state, grid


@pytest.fixture(scope="module")
def decision(study32, stalled_case):
    """One MPC decision from the stalled state, as the controller makes it (its 10-ms
    prediction model, the default options), compiled once for any surrogate:
    surrogate widths (V, t) -> (best plan, its predicted return, no shedding's)."""
    env, state, grid = stalled_case
    options = MpcOptions()
    planner, mpc, zeros = mpc_controller(env, options)
    decide_with = jax.jit(lambda g: decide(planner.prediction, options.iterations,
                                           jnp.asarray(zeros), state, study32.params, g, mpc))
    return lambda width, timer_width: decide_with(surrogate_model(grid, width, timer_width))


def test_one_decision_beats_no_shedding(study32, stalled_case, decision):
    env, state, grid = stalled_case
    assert np.any(np.asarray(state.grid.load_flags[0]["run_a"]) == 0.0), "motors stalled"
    options = MpcOptions()
    best_plan, best, no_shedding = decision(options.width, options.timer_width)
    assert float(best) > float(no_shedding) + 0.05 * abs(float(no_shedding)), \
        (float(best), float(no_shedding))
    assert float(jnp.max(best_plan)) <= -study32.params.action_low + 1e-7
    assert float(jnp.min(best_plan)) >= 0.0


def test_surrogate_changes_gradients_not_trajectories(decision):
    # the same start, predicted with and without the surrogate: the same return (the
    # trajectory is the exact model's), different ascent steps (its gradient is not)
    plan0, _, start0 = decision(0.0, 0.0)
    plan1, _, start1 = decision(0.05, 0.05)
    assert float(start0) == float(start1), "the surrogate leaves the predicted return unchanged"
    assert not np.array_equal(np.asarray(plan0), np.asarray(plan1)), "but not its gradient"


def test_options_parse_and_name_the_bad_one(study32):
    assert parse_options("") == MpcOptions()
    assert parse_options("horizon=2,iterations=5,every=2") == MpcOptions(
        horizon=2.0, iterations=5, every=2)
    with pytest.raises(ValueError, match=r"horizon = -1.0: must lie in \(0, 30\] s"):
        parse_options("horizon=-1")
    with pytest.raises(ValueError, match="name=value with name one of"):
        parse_options("depth=3")
    with pytest.raises(ValueError, match="every = '2.5': not an int"):
        parse_options("every=2.5")
    assert isinstance(mpc_controller(study32.env())[1], MpcParams)
