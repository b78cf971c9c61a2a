"""Learning curves: the trailing average that smooths a reward per iteration, and the figure
both training commands save (reward per episode against iterations or environment steps)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

SMOOTHING = 20  # iterations: the tasks drawn change from one iteration to the next


def smoothed(values: np.ndarray, window: int = SMOOTHING) -> np.ndarray:
    """Trailing moving average along the last axis (..., n) -> (..., n − window + 1)."""
    kernel = np.ones(window) / window
    return np.apply_along_axis(lambda v: np.convolve(v, kernel, "valid"), -1, values)


def pars_curve(log: list[dict], path: Path, study: str) -> None:
    """learning_curve.png of a PARS run's metrics rows: the mean and the best direction's
    reward per iteration (means over seeds), and the SMOOTHING-iteration average."""
    it = np.array([m["iteration"] for m in log])
    mean = np.array([m["reward_mean"] for m in log], float).reshape(len(log), -1).mean(1)
    best = np.array([m["reward_max"] for m in log], float).reshape(len(log), -1).mean(1)
    seeds = np.size(log[0]["reward_mean"])
    over = f", mean of {seeds} seeds" if seeds > 1 else ""
    fig, ax = _figure()
    ax.plot(it, mean, label="mean over perturbed rollouts" + over)
    ax.plot(it, best, alpha=0.6, label="best direction" + over)
    if len(log) > SMOOTHING:
        ax.plot(it[SMOOTHING - 1:], smoothed(mean), "k", lw=1.5,
                label=f"mean, {SMOOTHING}-iteration average")
    _save(fig, ax, path, "iteration", f"PARS on {study}")


def ppo_curve(log: list[dict], path: Path, study: str, n_tasks: int) -> None:
    """learning_curve.png of a PPO run's metrics rows: the deterministic policy's mean reward
    over the n_tasks training tasks, and the episodes that ended during collection, against
    environment steps."""
    steps = np.array([m["env_steps"] for m in log])
    fig, ax = _figure()
    ax.plot(steps, [m["reward_mean"] for m in log], "o-", ms=3,
            label=f"deterministic policy, mean over the {n_tasks} training tasks")
    train = [(s, m["reward_train"]) for s, m in zip(steps, log) if m["reward_train"] is not None]
    if train:
        ax.plot(*zip(*train), alpha=0.6, label="episodes ended during collection")
    _save(fig, ax, path, "environment steps", f"PPO on {study}")


def _figure():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(figsize=(7, 4))


def _save(fig, ax, path: Path, xlabel: str, title: str) -> None:
    """Label, title, legend and grid a learning curve (reward per episode) and save it."""
    import matplotlib.pyplot as plt

    ax.set_xlabel(xlabel)
    ax.set_ylabel("reward per episode")
    ax.set_title(title)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
