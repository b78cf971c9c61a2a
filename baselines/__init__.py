"""baselines: rule-based and other reference controllers for the load-shedding environment."""
from baselines.uvls import UvlsParams, UvlsState, check_params, relay_step, uvls_policy

__all__ = ["UvlsParams", "UvlsState", "check_params", "relay_step", "uvls_policy"]
