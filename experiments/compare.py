"""Compare controllers task by task from `experiments.evaluate` result files.

    python -m experiments.compare runs/none.json runs/uvls.json runs/policy.json
    python -m experiments.compare runs/rlgc.json --out runs/rlgc_log.json --plot DIR

The first file is the reference that decides which tasks need shedding: those it does not
recover. Prints, per controller, the summary (recovered, mean reward, MW shed), and for each
later controller against each earlier one on the tasks that need shedding: on how many it
earns the higher reward, how many it recovers, and the others by what each recovered
(`experiments.common.scores.losses`). A result of a published network whose
training log has rewards for its tasks ("log_reward", `experiments.evaluate`) is also set
against that log task by task: our reward, MW shed and verdict beside the logged reward
("against_log"), drawn with `--plot DIR` as DIR/<folder>_<file>_log.png. `--out` writes the
same as JSON.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from experiments.common.scores import losses


def _key(task: dict) -> tuple:
    return (task["fault_bus"], task["fault_duration"], task.get("fault_start"),
            task["operating_point"])


def load(path: str) -> dict:
    """An evaluate result with its tasks keyed by (fault bus, duration, start, operating
    point)."""
    result = json.loads(Path(path).read_text())
    return {"controller": result["controller"], "summary": result["summary"],
            "study": result.get("study"), "log": result.get("log"),
            "tasks": {_key(t): t for t in result["tasks"]}}


def against_log(result: dict) -> list[dict]:
    """The tasks of a loaded result that its training log has a reward for: fault bus,
    duration (s), reward, log_reward, shed_mw, recovered; [] without a log."""
    fields = ("fault_bus", "fault_duration", "reward", "log_reward", "shed_mw", "recovered")
    return [{f: t[f] for f in fields} for t in result["tasks"].values()
            if t.get("log_reward") is not None]


def compare(results: list[dict]) -> dict:
    """Summaries and pairwise wins on the tasks the first result does not recover."""
    reference = results[0]
    for other in results[1:]:
        if other["tasks"].keys() != reference["tasks"].keys():
            raise ValueError(f"{other['controller']} ran other tasks than "
                             f"{reference['controller']}")
    need = [k for k, t in reference["tasks"].items() if not t["recovered"]]
    report = {"reference": reference["controller"], "n_tasks": len(reference["tasks"]),
              "need_shedding": len(need),
              "summaries": {r["controller"]: r["summary"] for r in results}, "pairs": []}
    for i, later in enumerate(results[1:], start=1):
        for earlier in results[1:i]:
            wins = sum(later["tasks"][k]["reward"] > earlier["tasks"][k]["reward"] for k in need)
            report["pairs"].append({
                "controller": later["controller"], "against": earlier["controller"],
                "higher_reward_on": wins,
                "recovered": sum(later["tasks"][k]["recovered"] for k in need),
                "against_recovered": sum(earlier["tasks"][k]["recovered"] for k in need),
                "not_higher_on": losses(earlier["tasks"], later["tasks"], need),
                "sheds_where_not_needed": sum(
                    later["tasks"][k]["shed_mw"] > 0 for k in reference["tasks"]
                    if k not in need)})
    report["against_log"] = {r["controller"]: {"study": r["study"], "log": r["log"],
                                               "tasks": against_log(r)}
                             for r in results if against_log(r)}
    return report


def _file(controller: str) -> Path:
    """The file of a controller spec ("rlgc:FILE")."""
    return Path(controller.partition(":")[2])


def plot_against_log(controller: str, entry: dict, path: Path) -> None:
    """Our reward beside the logged one per task (symmetric-log axis) above our MW shed,
    with the tasks we do not recover marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = entry["tasks"]
    x = np.arange(len(tasks))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True,
                                      gridspec_kw={"height_ratios": [2, 1]})
    top.bar(x - 0.2, [t["reward"] for t in tasks], 0.4, label=f"ours ({entry['study']})")
    top.bar(x + 0.2, [t["log_reward"] for t in tasks], 0.4,
            label=f"training log (iteration {entry['log']['iteration']})")
    top.set_yscale("symlog", linthresh=10)
    top.set_ylabel("episode reward")
    top.axhline(0, color="k", lw=0.5)
    top.legend(fontsize=8, ncol=2, loc="lower center", bbox_to_anchor=(0.5, 1.0),
               frameon=False)
    file = _file(controller)
    fig.suptitle(f"{file.parent.name}/{file.name}: reward per task of its training log",
                 fontsize=10)
    bottom.bar(x, [t["shed_mw"] for t in tasks], 0.5, color="tab:gray")
    failed = [i for i, t in enumerate(tasks) if not t["recovered"]]
    bottom.plot(failed, [tasks[i]["shed_mw"] for i in failed], "rx", label="not recovered")
    if failed:
        bottom.legend(fontsize=8)
    bottom.set_ylabel("ours: MW shed")
    bottom.set_xticks(x, [f"bus {t['fault_bus']}\n{t['fault_duration']:g} s" for t in tasks],
                      fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("results", nargs="+", help="evaluate JSON files; the first is the "
                                                   "reference (usually --controller none)")
    parser.add_argument("--out", help="write the comparison as JSON")
    parser.add_argument("--plot", help="folder for the figures of results against their "
                                       "training logs")
    args = parser.parse_args(argv)
    report = compare([load(p) for p in args.results])
    for name, s in report["summaries"].items():
        print(f"{name:>40}: recovered {s['n_recovered']}/{s['n_tasks']}, mean reward "
              f"{s['mean_reward']:.1f}, shed {s['total_shed_mw']:.0f} MW")
    print(f"tasks that {report['reference']} does not recover: {report['need_shedding']}")
    for pair in report["pairs"]:
        print(f"{pair['controller']} vs {pair['against']}: higher reward on "
              f"{pair['higher_reward_on']}/{report['need_shedding']}, recovers "
              f"{pair['recovered']} (vs {pair['against_recovered']}); sheds on "
              f"{pair['sheds_where_not_needed']} tasks that need none")
        kinds = {k: n for k, n in pair["not_higher_on"].items() if n}
        if kinds:
            print("  not higher on: " + ", ".join(f"{n} {k.replace('_', ' ')}"
                                                 for k, n in kinds.items()))
    for name, entry in report["against_log"].items():
        print(f"{name} against {entry['log']['path']} (iteration {entry['log']['iteration']}):")
        print(f"{'bus':>5} {'fault s':>8} {'reward':>9} {'log':>9} {'MW shed':>8}  recovered")
        for t in entry["tasks"]:
            print(f"{t['fault_bus']:>5} {t['fault_duration']:>8.2f} {t['reward']:>9.1f} "
                  f"{t['log_reward']:>9.1f} {t['shed_mw']:>8.1f}  {t['recovered']}")
        if args.plot:
            figure = Path(args.plot) / f"{_file(name).parent.name}_{_file(name).stem}_log.png"
            plot_against_log(name, entry, figure)
            print(f"  figure: {figure}")
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
