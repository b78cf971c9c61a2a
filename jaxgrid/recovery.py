"""Voltage-recovery criteria of the FIDVR load-shedding study (PNNL PARS, 2022).

After a fault is cleared, a bus voltage should climb above a stepped envelope:
0.7 p.u. over (0, 0.33] s after clearing, 0.8 over (0.33, 0.5], 0.9 over (0.5, 1.5] and
0.95 after 1.5 s. Works with NumPy and jax.numpy arrays alike.

"Normal operation" of a bus, which the study's reward charges a shedding request in (the
paper: an invalid action is one "when the system is within normal operation"), is read as its
authors' GridPACK environment reads it to mask actions (pnnl/HADREC,
`GridPackPowerDynSimEnvDef_v10.py`): after clearing, the bus voltage at or above the level the
envelope asks next, 0.8 p.u. over (0, 0.33] s, 0.9 over (0.33, 0.5] and 0.95 after 0.5 s. That
environment also holds every request for the first 0.15 s after clearing (`MASK_HOLD`).

Undervoltage supervision (`supervision_allows`, not the study's) arms a bus's shedding only
while its voltage is below a level after clearing, as an undervoltage-supervised special
protection scheme does; with the recovery level (0.95 p.u.) it drops a request at a bus that
has already recovered.
"""
from __future__ import annotations

import numpy as np

ENVELOPE_TIMES = (0.0, 0.33, 0.5, 1.5)  # s after clearing, start of each level
ENVELOPE_LEVELS = (0.7, 0.8, 0.9, 0.95)  # p.u.
NORMAL_TIMES = (0.0, 0.33, 0.5)  # s after clearing, start of each normal-operation level
NORMAL_LEVELS = (0.8, 0.9, 0.95)  # p.u.
MASK_HOLD = 0.15  # s after clearing before which HADREC's environment sheds nothing


def _stepped(t_after_clearing, times, levels, xp):
    t = xp.asarray(t_after_clearing)
    level = xp.full(t.shape, np.nan)
    for start, value in zip(times, levels):
        level = xp.where(t > start, value, level)
    return level


def envelope(t_after_clearing, xp=np):
    """Recovery envelope (p.u.) at times after clearing (s, any shape); nan at or before 0."""
    return _stepped(t_after_clearing, ENVELOPE_TIMES, ENVELOPE_LEVELS, xp)


def normal_operation(vm, t_after_clearing, xp=np):
    """Bool, broadcast of vm (p.u.) and t_after_clearing (s): the bus is in normal operation
    (module docstring); never at or before clearing (the fault's own time and the time before
    it: the pre-fault penalty covers requests before the fault)."""
    level = _stepped(t_after_clearing, NORMAL_TIMES, NORMAL_LEVELS, xp)
    return ~xp.isnan(level) & (vm >= xp.where(xp.isnan(level), 0.0, level))


def mask_allows(vm, t_after_clearing, xp=np):
    """Bool, broadcast of vm (p.u.) and t_after_clearing (s): HADREC's action mask lets the bus
    shed (not in normal operation and at least `MASK_HOLD` after clearing)."""
    t = xp.asarray(t_after_clearing)
    return (t >= MASK_HOLD) & ~normal_operation(vm, t, xp)


def supervision_allows(vm, t_after_clearing, level, xp=np):
    """Bool, broadcast of vm (p.u.) and t_after_clearing (s): undervoltage supervision lets the
    bus shed unless it is at or above `level` (p.u.) after clearing (at and before clearing
    it leaves requests alone: the pre-fault penalty covers requests before the fault)."""
    return ~((xp.asarray(t_after_clearing) > 0) & (vm >= level))
