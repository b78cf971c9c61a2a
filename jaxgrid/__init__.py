"""jaxgrid: a JAX-native, batched power-grid simulator for FIDVR load-shedding studies."""
