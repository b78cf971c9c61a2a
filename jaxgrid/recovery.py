"""Voltage-recovery criteria of the FIDVR load-shedding study (PNNL PARS, 2022).

After a fault is cleared, a bus voltage should climb above a stepped envelope:
0.7 p.u. over (0, 0.33] s after clearing, 0.8 over (0.33, 0.5], 0.9 over (0.5, 1.5] and
0.95 after 1.5 s. Works with NumPy and jax.numpy arrays alike.
"""
from __future__ import annotations

import numpy as np

ENVELOPE_TIMES = (0.0, 0.33, 0.5, 1.5)  # s after clearing, start of each level
ENVELOPE_LEVELS = (0.7, 0.8, 0.9, 0.95)  # p.u.


def envelope(t_after_clearing, xp=np):
    """Recovery envelope (p.u.) at times after clearing (s, any shape); nan at or before 0."""
    t = xp.asarray(t_after_clearing)
    level = xp.full(t.shape, np.nan)
    for start, value in zip(ENVELOPE_TIMES, ENVELOPE_LEVELS):
        level = xp.where(t > start, value, level)
    return level
