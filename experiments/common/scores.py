"""A controller's record per kind of task, the measure of the paper-claims comparisons.

The tasks of a set fall into two kinds by what happens without control (`none`): those it
does not recover *need shedding*, the others *need none*. On the first kind a controller is
measured against UVLS (the paper: "PARS outperformed the UVLS for all the tasks that required
load shedding"): on how many it earns the higher reward and how many it recovers; on the
second by whether it sheds at all (at least `SHEDS_MW`); the need tasks it does not win are
counted by what each controller's verdict was (`losses`), which says why it loses. All three
results are `experiments.common.evaluation.evaluate` dicts of the same tasks.
"""
from __future__ import annotations

SHEDS_MW = 1.0  # a task on which a controller sheds less than this counts as "sheds nothing"
# the kinds of a lost task (`losses`): the same reward (e.g. neither acts), then by verdicts
LOSS_KINDS = ("tie", "both_recover", "both_fail", "it_fails", "it_recovers")


def _by_task(result: dict) -> dict:
    return {(t["fault_bus"], t["fault_duration"], t["fault_start"], t["point"]): t
            for t in result["tasks"]}


def losses(other: dict, mine: dict, keys) -> dict:
    """Of the tasks `keys` on which `mine` earns no more reward than `other` (both dicts of
    task records by key), how many of each of `LOSS_KINDS`: "tie" the same reward, else
    "both_recover" (it sheds more or recovers later), "both_fail", "it_fails" (where the other
    recovers), "it_recovers" (where the other fails, yet earns less)."""
    counts = dict.fromkeys(LOSS_KINDS, 0)
    for k in keys:
        if mine[k]["reward"] > other[k]["reward"]:
            continue
        if mine[k]["reward"] == other[k]["reward"]:
            kind = "tie"
        else:
            kind = {(True, True): "both_recover", (False, False): "both_fail",
                    (False, True): "it_fails", (True, False): "it_recovers"}[
                (bool(mine[k]["recovered"]), bool(other[k]["recovered"]))]
        counts[kind] += 1
    return counts


def scores(none: dict, uvls: dict, result: dict) -> dict:
    """The record of `result` (module docstring): need (tasks that need shedding), wins (of
    them, reward above UVLS's), recovered and uvls_recovered (of them), mw_need (MW shed per
    such task), losses (of them, those it does not win by kind: `losses` against UVLS), ok
    (tasks that need none), sheds_on (of them, with >= SHEDS_MW shed), mw_ok (MW per such
    task), mean_reward (all tasks), n_tasks. ValueError if the three ran other tasks."""
    reference, relay, mine = _by_task(none), _by_task(uvls), _by_task(result)
    if not reference.keys() == relay.keys() == mine.keys():
        raise ValueError(f"{result['controller']}, uvls and none ran different tasks")
    need = [k for k, t in reference.items() if not t["recovered"]]
    ok = [k for k, t in reference.items() if t["recovered"]]
    mean = lambda values: sum(values) / len(values) if values else 0.0  # noqa: E731
    return {"n_tasks": len(mine), "need": len(need),
            "wins": sum(mine[k]["reward"] > relay[k]["reward"] for k in need),
            "recovered": sum(mine[k]["recovered"] for k in need),
            "uvls_recovered": sum(relay[k]["recovered"] for k in need),
            "mw_need": mean([mine[k]["shed_mw"] for k in need]),
            "losses": losses(relay, mine, need),
            "ok": len(ok), "sheds_on": sum(mine[k]["shed_mw"] >= SHEDS_MW for k in ok),
            "mw_ok": mean([mine[k]["shed_mw"] for k in ok]),
            "mean_reward": mean([t["reward"] for t in mine.values()])}


def targets_met(record: dict, wins: float = 0.95, quiet: float = 0.95) -> dict:
    """The paper-claims targets of a `scores` record: beats UVLS on >= `wins` of the tasks
    that need shedding, recovers at least as many of them as UVLS, sheds nothing on >=
    `quiet` of the tasks that need none (a kind with no tasks meets its targets)."""
    need, ok = record["need"], record["ok"]
    return {"wins": need == 0 or record["wins"] >= wins * need,
            "recovers": record["recovered"] >= record["uvls_recovered"],
            "quiet": ok == 0 or ok - record["sheds_on"] >= quiet * ok}
