"""Parallel Augmented Random Search (PARS) for any functional environment.

The package knows nothing about grids and imports nothing from `jaxgrid`: it needs an episode
function `episode(policy_apply, policy_params, task, policy_carry, data) -> {"reward",
"policy_carry", ...}` that calls `policy_apply(policy_params, obs, carry, inputs) ->
(action, carry)` (`inputs`: whatever else the episode gives its controllers, unused by the
policy) and a pytree of tasks with a leading axis (`ars.pars.make_iteration`);
`ars.train.train(config, problem)` runs a whole training on such a problem (checkpoints,
resume, seeds, metrics). How the rollouts are batched is passed in (`ars.pars.Vmaps`).
"""
