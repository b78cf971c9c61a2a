"""The one error measure of jaxgrid beside a reference simulator (ANDES:
`experiments.reference.andes_files.trajectory_errors`; GridPACK:
`experiments.reference.comparison.compare`): the largest and the root-mean-square absolute
difference of two series on one time grid (`deviation`) over the samples a window keeps,
after one series is resampled linearly onto the other's times (`at_times`).

Each harness states its grid and its window. ANDES stamps an event's time twice (before and
after it) and its steps drift off the grid by rounding, so its run is resampled onto jaxgrid's
samples, and the samples within 30 ms after each event are left out. jaxgrid's run is resampled
onto GridPACK's samples (both step alike; GridPACK's clearing sample is the cleared network),
and every sample from clearing on is kept. Resampled across an event, a series mixes the
network before and after it: which way to resample is chosen so that no kept sample does.
"""
from __future__ import annotations

import numpy as np


def at_times(t, t_from, values) -> np.ndarray:
    """`values` ((n_from,) or (n_from, k), sampled at t_from s) linearly interpolated at the
    times t (n_t,) s."""
    values = np.asarray(values)
    if values.ndim == 1:
        return np.interp(t, t_from, values)
    return np.stack([np.interp(t, t_from, values[:, k]) for k in range(values.shape[1])],
                    axis=1)


def deviation(ours, ref, keep) -> tuple[float, float]:
    """(largest, RMS) |ours − ref| over the samples `keep` (n_t,) bool of two series on one
    time grid ((n_t,) or (n_t, k)), in the values' unit; NaN samples (a quantity one
    simulator does not have at a time) left out."""
    diff = np.abs(np.asarray(ours) - np.asarray(ref))[np.asarray(keep)]
    return float(np.nanmax(diff)), float(np.sqrt(np.nanmean(diff ** 2)))
