"""Parallel Augmented Random Search (PARS) for any functional environment.

The package knows nothing about grids: it needs an episode function
`episode(policy_apply, policy_params, task, policy_carry) -> {"reward", "policy_carry", ...}`
and a pytree of tasks with a leading axis (see `ars.pars.make_iteration`).
"""
