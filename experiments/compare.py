"""Compare controllers task by task from `experiments.evaluate` result files.

    python -m experiments.compare results/none.json results/uvls.json results/policy.json

The first file is the reference that decides which tasks need shedding: those it does not
recover. Prints, per controller, the summary (recovered, mean reward, MW shed), and for each
later controller against each earlier one on the tasks that need shedding: on how many it
earns the higher reward and how many it recovers. `--out` writes the same as JSON.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path


def _key(task: dict) -> tuple:
    return (task["fault_bus"], task["fault_duration"], task.get("fault_start"),
            task["operating_point"])


def load(path: str) -> dict:
    """An evaluate result with its tasks keyed by (fault bus, duration, start, operating
    point)."""
    result = json.loads(Path(path).read_text())
    return {"controller": result["controller"], "summary": result["summary"],
            "tasks": {_key(t): t for t in result["tasks"]}}


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
                "sheds_where_not_needed": sum(
                    later["tasks"][k]["shed_mw"] > 0 for k in reference["tasks"]
                    if k not in need)})
    return report


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("results", nargs="+", help="evaluate JSON files; the first is the "
                                                   "reference (usually --controller none)")
    parser.add_argument("--out", help="write the comparison as JSON")
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
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
