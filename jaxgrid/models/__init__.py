"""Dynamic device models, one family per module (machines, exciters, governors, loads)."""
