"""Parallel Augmented Random Search (PARS) for any functional environment.

The package knows nothing about grids and imports nothing from `jaxgrid`. An iteration is a
search strategy's `ask`/`tell` (`ars.pars.Pars`; `ars.es.PlainEs`) composed with a problem's
`evaluate(thetas, shared, tasks, data)`, which runs every parameter vector's episodes with
the controller `policy_apply(params, obs, carry, inputs) -> (action, carry)` (the policy with
its observation normaliser, `ars.normalizer.normalized_policy`; `inputs`: whatever else the
episode gives its controllers, unused by the policy) and owns how they are batched and
sharded (`ars.iteration.make_iteration`); `ars.train.train(config, problem)` runs a whole
training on such a problem (checkpoints, resume, seeds, metrics).
"""
