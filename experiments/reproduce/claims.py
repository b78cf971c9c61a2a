"""The PARS paper's side claims, computed from `experiments.evaluate` results and traces.

Plain functions of plain dicts (an evaluate result: {"tasks": [{"fault_bus",
"fault_duration", "fault_start", "operating_point", "reward", "shed_mw", "recovered"}]}; a
trace of `runs.Runs.trace`), so each claim can be checked on inputs whose answer is
known by hand:
  - the share of test tasks on which PARS earns more than a baseline, and on which the
    difference passes a threshold (more than M over UVLS, less than M/2 against PPO; M the
    failure penalty, 10 000 on the 300-bus);
  - how many tasks a controller fails (does not recover);
  - on the tasks that need shedding (not recovered without control), where PARS does not
    beat UVLS;
  - the buses a controller leaves below the recovery level (the bus-23 case study);
  - the best PPO seed, by its final reward on the training tasks.
"""
from __future__ import annotations

import numpy as np


def task_key(task: dict) -> tuple:
    """(fault bus, duration s, start s, operating point label) of an evaluated task."""
    return (task["fault_bus"], task["fault_duration"], task.get("fault_start"),
            task["operating_point"])


def paired_rewards(ours: dict, other: dict) -> tuple[np.ndarray, np.ndarray]:
    """(n,) rewards of two evaluate results on the same tasks, in `ours`' order; ValueError
    if they ran different tasks."""
    theirs = {task_key(t): t["reward"] for t in other["tasks"]}
    keys = [task_key(t) for t in ours["tasks"]]
    if set(keys) != set(theirs) or len(keys) != len(theirs):
        raise ValueError(f"{ours.get('controller')} and {other.get('controller')} ran "
                         "different tasks")
    return (np.array([t["reward"] for t in ours["tasks"]], float),
            np.array([theirs[k] for k in keys], float))


def percent(share: float) -> str:
    return f"{100 * share:.2f} %"


def difference_shares(ours: dict, other: dict, more_than: float | None = None,
                      less_than: float | None = None) -> dict:
    """Shares of tasks where ours − other is > 0 ("better"), >= 0 ("at least as good"),
    > `more_than` ("more than"), < `less_than` ("less than"), as 'P.PP %'."""
    mine, theirs = paired_rewards(ours, other)
    difference = mine - theirs
    shares = {"better": np.mean(difference > 0), "at least as good": np.mean(difference >= 0)}
    if more_than is not None:
        shares["more than"] = np.mean(difference > more_than)
    if less_than is not None:
        shares["less than"] = np.mean(difference < less_than)
    return {k: percent(float(v)) for k, v in shares.items()}


def failures(result: dict) -> str:
    """'k of n': the tasks `result` does not recover."""
    tasks = result["tasks"]
    return f"{sum(not t['recovered'] for t in tasks)} of {len(tasks)}"


def shedding_wins(none: dict, ours: dict, other: dict) -> dict:
    """On the tasks `none` (no control) does not recover: on how many ours earns more than
    `other`, and those where it does not ("bus B, D s, point P: ours R vs R'")."""
    need = {task_key(t) for t in none["tasks"] if not t["recovered"]}
    theirs = {task_key(t): t["reward"] for t in other["tasks"]}
    if not need <= set(theirs):
        raise ValueError(f"{other.get('controller')} did not run every task that needs "
                         "shedding")
    rows = [t for t in ours["tasks"] if task_key(t) in need]
    if len(rows) != len(need):
        raise ValueError(f"{ours.get('controller')} did not run every task that needs "
                         "shedding")
    losses = [f"bus {t['fault_bus']}, {t['fault_duration']:g} s, {t['operating_point']}: "
              f"{t['reward']:.1f} vs {theirs[task_key(t)]:.1f}"
              for t in rows if not t["reward"] > theirs[task_key(t)]]
    return {"tasks that need shedding": len(need),
            "better on tasks that need shedding": f"{len(need) - len(losses)} of {len(need)}",
            "not better on": losses}


def buses_not_recovered(trace: dict, level: float) -> list[int]:
    """Observed buses left below `level` p.u. by a failed episode: below it at the last step
    (the trace freezes there when the recovery check fails) though at or above it at the
    first (before the fault; buses low from the start are not checked). [] if recovered."""
    if trace["recovered"]:
        return []
    vm = np.asarray(trace["vm"])  # (steps, observed) p.u.
    return [bus for bus, before, last in zip(trace["observed"], vm[0], vm[-1])
            if before >= level and last < level]


def best_ppo_seed(rows_per_seed: list[list[dict]]) -> int:
    """Index of the PPO training whose last metrics line has the highest `reward_mean` (its
    deterministic policy on every training task: chosen without the test tasks)."""
    finals = [rows[-1]["reward_mean"] if rows else -np.inf for rows in rows_per_seed]
    return int(np.argmax(finals))
