"""ars: Parallel Augmented Random Search (PARS) for functional JAX environments."""
