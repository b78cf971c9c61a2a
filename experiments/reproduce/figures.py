"""The experiments of `experiments.reproduce`, named after the PARS paper's figures and tables.

Each experiment takes the `Runs` of a reproduction, gets the runs it needs from it (cached),
writes its figure `OUT/<id>.png`, and returns its numbers: {"numbers": {quantity: ours},
"settings": what ran}. `PAPER` holds, per experiment, its title, the paper's case and
settings, and the paper's values for the same quantities (from the paper's text, figures
and tables; "≈" marks values read off a figure). The side claims are computed by
`experiments.reproduce.claims`. `generalisation` is not in the paper: the main policy against
UVLS on the operating points it never trained on (the study's "generalisation" task set).
"""
from __future__ import annotations

import jax
import numpy as np

from ars.checkpoint import metrics_rows
from experiments.common.curves import smoothed
from experiments.reproduce import claims
from experiments.reproduce.runs import Runs, convergence_iteration

# what a convergence row holds for a run that settles only in its last window, if at all
NOT_SETTLED = "not settled"

PAPER = {
    "fig6a": {"title": "Learning curves of linear, FNN and LSTM policies (N = 16, 5 seeds)",
              "case": "IEEE 39-bus", "settings": "N = 16, b = 8, m = 9, 5 seeds",
              "values": {"best average reward, linear": -114.2,
                         "best average reward, fnn": -94.1,
                         "best average reward, lstm": -97.8}},
    "fig6b": {"title": "LSTM policy with N = 8, 16, 32, 64 directions",
              "case": "IEEE 39-bus", "settings": "b = N/2, m = 9",
              "values": {"best average reward, N=8": -158.4,
                         "best average reward, N=16": -97.8,
                         "best average reward, N=32": -94.0,
                         "best average reward, N=64": -88.3}},
    "fig7": {"title": "Speed-up against the number of workers (fixed work per iteration)",
             "case": "IEEE 300-bus", "settings": "3 to 1152 CPU cores (Ray)",
             "values": {"speed-up, largest against smallest": "136× (1152 vs 3 cores)"}},
    "fig8": {"title": "39-bus case study: fault at bus 3, 0.08 s; bus-4 voltage, MW shed",
             "case": "IEEE 39-bus", "settings": "fault at bus 3 for 0.08 s",
             "values": {"reward, PARS": -94.09, "reward, UVLS": -2367.21,
                        "PARS better than UVLS on tasks that need shedding (test set)": "all",
                        "tasks that need shedding where PARS is not better": "none"}},
    "fig9": {"title": "LSTM learning curves with N = 32, 64, 128 directions",
             "case": "IEEE 300-bus", "settings": "b = N/2",
             "values": {"note": "more directions learn faster and better"}},
    "fig10_11": {"title": "PARS against PPO: training reward over wall time and over "
                          "environment steps",
                 "case": "IEEE 300-bus", "settings": "PARS on Ray vs RLlib PPO, 500+ cores",
                 "values": {"wall-time speed-up to convergence, PPO / PARS": "≈5×"}},
    "fig12": {"title": "Per-task reward difference on the test tasks: PARS − UVLS / MPC / PPO",
              "case": "IEEE 300-bus", "settings": "170 test tasks",
              "values": {"PARS better than UVLS on": "98.82 %",
                         "PARS better than MPC on": "comparable",
                         "PARS better than PPO on": "95.29 %",
                         "PARS − UVLS more than M on": "> 50 %",
                         "PARS − PPO less than M/2 on": "≈ 85 %",
                         "M (failure penalty)": 10000,
                         "PPO fails on": "3 of 170",
                         "mean reward, PARS − MPC": "comparable"}},
    "tab3": {"title": "Decision time per control step", "case": "IEEE 300-bus",
             "settings": "PARS policy vs trajectory-sensitivity MPC",
             "values": {"PARS LSTM, s per decision": 0.72, "MPC, s per decision": 63.31}},
    "generalisation": {"title": "The trained policy against UVLS on operating points it never "
                                "trained on",
                       "case": "not in the paper", "settings": "-",
                       "values": {"note": "the paper claims generalisation to unseen "
                                          "scenarios, without this measurement"}},
    "fig13": {"title": "300-bus case study: fault at bus 23, 0.1 s; bus-33 voltage, MW shed",
              "case": "IEEE 300-bus", "settings": "fault at bus 23 for 0.1 s",
              "values": {"reward, PARS": -823.6, "reward, MPC": -876.6, "reward, PPO": -927.3,
                         "reward, UVLS": -21901.8, "buses not recovered, UVLS": 5,
                         "buses not recovered, PARS": 0, "buses not recovered, MPC": 0,
                         "buses not recovered, PPO": 0, "sheds the least": "PARS"}},
}


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _seeds(n: int) -> str:
    return f"{n} seed" if n == 1 else f"{n} seeds"


def _save(fig, path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _plt().close(fig)


def _curves(runs: Runs, configs: list[tuple[str, int, str]], title: str, path) -> dict:
    """Learning curves (mean ± std over seeds) of PARS runs (policy, N, label) on one figure;
    per run: best moving-average reward, convergence iteration, the median seconds per
    iteration on each device the run used (a run resumed elsewhere lists both)."""
    plt = _plt()
    window = runs.settings.window
    fig, ax = plt.subplots(figsize=(7, 4))
    numbers = {}
    for policy, directions, label in configs:
        curves = runs.pars_curves(runs.pars(policy, directions))
        it, reward = curves["iteration"], curves["reward"]
        mean, std = reward.mean(0), reward.std(0)
        line, = ax.plot(it, mean, lw=1, label=label)
        ax.fill_between(it, mean - std, mean + std, color=line.get_color(), alpha=0.2)
        average = smoothed(mean, min(window, len(mean)))
        numbers[f"best average reward, {label}"] = round(float(average.max()), 1)
        settled = convergence_iteration(it, mean, min(window, len(mean)))
        numbers[f"converged at iteration, {label}"] = NOT_SETTLED if settled is None else settled
        wall = np.diff(curves["wall_s"], prepend=0.0)  # per iteration; a start compiles
        for device in dict.fromkeys(curves["device"]):
            numbers[f"s per iteration ({_seeds(reward.shape[0])} in one program, median, "
                    f"{device}), {label}"] = round(
                float(np.median(wall[curves["device"] == device])), 2)
    ax.set_xlabel("iteration")
    ax.set_ylabel("reward per episode (mean of the perturbed rollouts)")
    ax.set_title(f"{title} — {runs.study.name}, mean ± std over {_seeds(runs.settings.seeds)}")
    ax.legend()
    ax.grid(alpha=0.3)
    _save(fig, path)
    return numbers


def fig6a(runs: Runs, path) -> dict:
    n = runs.directions
    numbers = _curves(runs, [(kind, n, kind) for kind in ("linear", "fnn", "lstm")],
                      f"PARS policies, N = {n}", path)
    history = ", ".join(f"{k} {runs.study.history(k)}" for k in ("linear", "fnn", "lstm"))
    return {"numbers": numbers, "settings": f"N = {n}, b = {max(1, n // 2)}, "
            f"m = {runs.settings.tasks_per_iteration}, {_seeds(runs.settings.seeds)}, "
            f"{runs.settings.iterations} iterations, observations stacked: {history}"}


def _sweep(runs: Runs, sweep, path) -> dict:
    numbers = _curves(runs, [("lstm", n, f"N={n}") for n in sweep], "LSTM policy", path)
    return {"numbers": numbers, "settings": f"LSTM, N = {list(sweep)}, b = N/2, "
            f"m = {runs.settings.tasks_per_iteration}, {_seeds(runs.settings.seeds)}, "
            f"{runs.settings.iterations} iterations"}


def fig6b(runs: Runs, path) -> dict:
    return _sweep(runs, runs.settings.sweep, path)


def fig9(runs: Runs, path) -> dict:
    return _sweep(runs, runs.settings.sweep_large, path)


def fig7(runs: Runs, path) -> dict:
    """Speed-up of one PARS iteration over 1, 2, ... devices of this process, over
    `processes` processes of one device each and, from `gpu_timing`, on one GPU."""
    plt = _plt()
    devices = jax.devices()
    counts = sorted({1, *[k for k in (2, 4, 8, 16) if k <= len(devices)], len(devices)})
    seconds = {f"{k} {devices[0].platform} device(s)": runs.iteration_seconds(k)
               for k in counts}
    workers = list(counts)
    if runs.settings.processes > 1:
        seconds[f"{runs.settings.processes} processes × 1 CPU device"] = runs.process_seconds(
            runs.settings.processes)
        workers.append(runs.settings.processes)
    if runs.settings.gpu_timing:
        label, row = runs.gpu_row()
        seconds[label] = row["s_per_iteration"]
        workers.append(1)
    base = seconds[f"1 {devices[0].platform} device(s)"]
    fig, ax = plt.subplots(figsize=(6, 4))
    for (label, s), k in zip(seconds.items(), workers):
        ax.plot(k, base / s, "o", label=label)
    ax.plot([1, max(workers)], [1, max(workers)], "k--", lw=1, label="linear")
    ax.set_xlabel("workers")
    ax.set_ylabel("speed-up of one iteration")
    ax.set_title(f"PARS speed-up, {runs.study.name}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    _save(fig, path)
    numbers = {f"s per iteration, {k}": round(v, 3) for k, v in seconds.items()}
    numbers.update({f"speed-up, {k}": round(base / v, 2) for k, v in seconds.items()})
    s = runs.settings
    return {"numbers": numbers, "settings": f"LSTM, N = {runs.directions}, m = "
            f"{s.tasks_per_iteration}, median of {s.timing_iterations} iterations"}


def _case_study(runs: Runs, path, controllers: dict, fault_bus: int, duration: float,
                bus: int) -> dict:
    """Voltage at `bus` (or the lowest observed bus, if it is not observed) and MW shed of
    each controller {label: spec} on one fault."""
    plt = _plt()
    traces = {label: runs.trace(spec, fault_bus, duration) for label, spec in
              controllers.items()}
    first = next(iter(traces.values()))
    observed = first["observed"]
    column = (observed.index(bus) if bus in observed
              else int(np.argmin(np.asarray(first["vm"])[-1])))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for label, trace in traces.items():
        top.plot(trace["t"], np.asarray(trace["vm"])[:, column], lw=1,
                 label=f"{label} ({trace['reward']:.1f})")
        bottom.step(trace["t"], trace["shed_mw"], where="post", label=label)
    top.set_ylabel(f"bus {observed[column]} voltage (p.u.)")
    top.set_title(f"{runs.study.name}: fault at bus {fault_bus}, {duration * 1000:.0f} ms"
                  + ("" if bus in observed else f" (bus {bus} is not observed here)"))
    top.legend(fontsize=8)
    bottom.set_ylabel("load shed (MW)")
    bottom.set_xlabel("time (s)")
    bottom.legend(fontsize=8)
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    _save(fig, path)
    numbers = {f"reward, {label}": round(t["reward"], 2) for label, t in traces.items()}
    numbers.update({f"MW shed, {label}": round(t["shed_mw"][-1], 1)
                    for label, t in traces.items()})
    return {"numbers": numbers, "settings": f"fault at bus {fault_bus} for {duration} s at "
            f"the first operating point; voltage of bus {observed[column]}; controllers "
            + ", ".join(f"{k} {v}" for k, v in controllers.items())}


def fig8(runs: Runs, path) -> dict:
    """The bus-3 case study, and the 39-bus claim on the test set: PARS beats UVLS on every
    task that needs shedding (fails without control), or the tasks where it does not."""
    policy = runs.main_policy()
    result = _case_study(runs, path, {"PARS": policy, "UVLS": "uvls"}, 3, 0.08, 4)
    wins = claims.shedding_wins(runs.evaluation("none"), runs.evaluation(policy),
                                runs.evaluation("uvls"))
    result["numbers"].update({
        "PARS better than UVLS on tasks that need shedding (test set)":
            wins["better on tasks that need shedding"],
        "tasks that need shedding where PARS is not better":
            "; ".join(wins["not better on"]) or "none"})
    return result


def _ppo_policy(runs: Runs) -> str:
    """The given PPO policy, or the best of the `ppo_seeds` PPO trainings."""
    if runs.settings.ppo_policy:
        return f"ppo:{runs.settings.ppo_policy}"
    return runs.best_ppo(_ppo_steps(runs))


def _baselines(runs: Runs) -> dict:
    """{label: controller spec} of the baselines PARS is compared with: UVLS, MPC and PPO,
    less `settings.skip_baselines` (PPO is trained here when it is needed)."""
    skip = runs.settings.skip_baselines
    return {"UVLS": "uvls", **({} if "mpc" in skip else {"MPC": "mpc"}),
            **({} if "ppo" in skip else {"PPO": _ppo_policy(runs)})}


def _ppo_steps(runs: Runs) -> int:
    """PPO environment steps: the settings', or as many as one PARS training."""
    s = runs.settings
    if s.ppo_env_steps is not None:
        return s.ppo_env_steps
    steps = int(round(runs.study.config.episode / runs.study.config.agent_dt))
    return s.iterations * 2 * runs.directions * s.tasks_per_iteration * steps


def fig13(runs: Runs, path) -> dict:
    """The bus-23 case study: rewards, MW shed, who sheds least, and how many observed buses
    each controller leaves below the recovery level (the paper: five under UVLS)."""
    controllers = {"PARS": runs.main_policy(), **_baselines(runs)}
    result = _case_study(runs, path, controllers, 23, 0.1, 33)
    level = runs.study.params.recovery_level
    for label, spec in controllers.items():
        result["numbers"][f"buses not recovered, {label}"] = len(
            claims.buses_not_recovered(runs.trace(spec, 23, 0.1), level))
    shed = {label: result["numbers"][f"MW shed, {label}"] for label in controllers}
    result["numbers"]["sheds the least"] = ", ".join(
        label for label, mw in shed.items() if mw == min(shed.values()))  # ties: all
    result["settings"] += _skipped(runs)
    return result


def _skipped(runs: Runs) -> str:
    """'; left out: MPC, PPO' for the settings line of an experiment without them."""
    skip = runs.settings.skip_baselines
    return f"; left out: {', '.join(b.upper() for b in skip)}" if skip else ""


def fig10_11(runs: Runs, path) -> dict:
    """Training reward of PARS (the main LSTM run, every seed: mean over its perturbed
    rollouts) and PPO (`ppo_seeds` runs: mean return of the episodes each chunk ended)
    against wall time per seed and environment steps (PARS: the agent steps its episodes
    simulated, mean over seeds; a failed episode stops early). PARS's seeds train together in
    one program, PPO's one after another: a PARS seed's wall time is the program's over its
    seeds, so that both are compared per seed."""
    s = runs.settings
    if "ppo" in s.skip_baselines:
        raise NotApplicable("PPO is left out (--skip-baselines)")
    plt = _plt()
    pars = runs.pars_curves(runs.pars("lstm", runs.directions))
    ppo_rows = [metrics_rows(runs.ppo(seed, _ppo_steps(runs)) / "metrics.jsonl")
                for seed in range(s.ppo_seeds)]
    n = min(len(rows) for rows in ppo_rows)
    ppo_reward = np.array([[r["reward_train"] if r["reward_train"] is not None else np.nan
                            for r in rows[:n]] for rows in ppo_rows], float)
    ppo_wall = np.mean([[r["wall_total_s"] for r in rows[:n]] for rows in ppo_rows], 0)
    ppo_steps = np.array([r["env_steps"] for r in ppo_rows[0][:n]])
    pars_wall = pars["wall_s"] / pars["reward"].shape[0]
    curves = {"PARS": (pars_wall, pars["env_steps"].mean(0), pars["reward"]),
              "PPO": (ppo_wall, ppo_steps, ppo_reward)}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    numbers, to_convergence = {}, {}
    for label, (wall, env_steps, reward) in curves.items():
        kept = np.isfinite(reward).any(0)  # PPO chunks in which no episode ended are left out
        wall, env_steps, reward = wall[kept], env_steps[kept], reward[:, kept]
        mean, std = np.nanmean(reward, 0), np.nanstd(reward, 0)
        for ax, x in zip(axes, (wall, env_steps)):
            line, = ax.plot(x, mean, lw=1, label=f"{label} ({_seeds(reward.shape[0])})")
            ax.fill_between(x, mean - std, mean + std, color=line.get_color(), alpha=0.2)
        # the moving-average window spans as many environment steps as PARS's
        span = s.window * (curves["PARS"][1][0] if len(curves["PARS"][1]) else 1)
        window = int(np.clip(round(span / max(env_steps[0], 1)), 1, len(mean)))
        settled = convergence_iteration(np.arange(len(mean)), mean, window)
        numbers[f"final training reward, {label}"] = round(float(smoothed(mean, window)[-1]),
                                                           1)
        to_convergence[label] = None if settled is None else round(float(wall[settled]), 1)
        numbers[f"wall s to convergence, {label}"] = (NOT_SETTLED if settled is None
                                                     else to_convergence[label])
        numbers[f"wall s in all, {label}"] = round(float(wall[-1]), 1)
    if None not in to_convergence.values():
        numbers["wall-time speed-up to convergence, PPO / PARS"] = round(
            to_convergence["PPO"] / max(to_convergence["PARS"], 1e-9), 2)
    axes[0].set_xlabel("wall time per seed (s)")
    axes[1].set_xlabel("environment steps (agent steps of 0.1 s)")
    axes[0].set_ylabel("training reward per episode")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"PARS vs PPO on {runs.study.name}")
    _save(fig, path)
    numbers["environment steps, PARS (mean over seeds)"] = int(curves["PARS"][1][-1])
    numbers["environment steps, PPO"] = int(ppo_steps[-1])
    return {"numbers": numbers, "settings": f"PARS LSTM N = {runs.directions}, "
            f"{s.iterations} iterations × {_seeds(s.seeds)} in one program; PPO {s.ppo_seeds} "
            f"seeds × {_ppo_steps(runs)} env steps (Table II settings"
            f"{'; ' + ' '.join(s.ppo_flags) if s.ppo_flags else ''}), one after another; "
            "wall times per seed"}


def fig12(runs: Runs, path) -> dict:
    """Per-task reward differences on the test set and the paper's side claims: shares of
    tasks PARS wins, PARS − UVLS more than M, PARS − PPO less than M/2 (M the failure
    penalty), the tasks each controller fails, PARS's mean reward against MPC's."""
    plt = _plt()
    pars = runs.evaluation(runs.main_policy())
    others = {label: runs.evaluation(spec) for label, spec in _baselines(runs).items()}
    penalty = abs(runs.study.params.unstable_penalty)
    thresholds = {"UVLS": {"more_than": penalty}, "PPO": {"less_than": penalty / 2}}
    fig, axes = plt.subplots(1, len(others), figsize=(4.4 * len(others), 3.8), squeeze=False)
    axes = axes[0]
    numbers = {"test tasks": len(pars["tasks"]), "M (failure penalty)": penalty}
    for ax, (label, result) in zip(axes, others.items()):
        shares = claims.difference_shares(pars, result, **thresholds.get(label, {}))
        numbers[f"PARS better than {label} on"] = shares["better"]
        numbers[f"PARS at least as good as {label} on"] = shares["at least as good"]
        if "more than" in shares:
            numbers[f"PARS − {label} more than M on"] = shares["more than"]
        if "less than" in shares:
            numbers[f"PARS − {label} less than M/2 on"] = shares["less than"]
        numbers[f"{label} fails on"] = claims.failures(result)
        numbers[f"mean reward, {label}"] = round(result["summary"]["mean_reward"], 1)
        ours, theirs = claims.paired_rewards(pars, result)
        ax.hist(ours - theirs, bins=20)
        ax.axvline(0, color="k", lw=1)
        ax.set_title(f"PARS − {label}: PARS better on {shares['better']}")
        ax.set_xlabel("reward difference per task")
    numbers["PARS fails on"] = claims.failures(pars)
    numbers["mean reward, PARS"] = round(pars["summary"]["mean_reward"], 1)
    if "MPC" in others:
        numbers["mean reward, PARS − MPC"] = round(numbers["mean reward, PARS"]
                                                   - numbers["mean reward, MPC"], 1)
    axes[0].set_ylabel("test tasks")
    _save(fig, path)
    ppo = (f", PPO (best of {runs.settings.ppo_seeds} seeds) {others['PPO']['controller']}"
           if "PPO" in others else "")
    return {"numbers": numbers, "settings": f"{len(pars['tasks'])} test tasks of "
            f"{runs.study.name}; PARS {pars['controller']}{ppo}{_skipped(runs)}"}


def _trained_policies(runs: Runs) -> dict:
    """{label: policy folder}: the main LSTM policy, and fig6a's linear and FNN ones (best
    seeds) where those trainings are finished."""
    lstm = runs.main_policy().removeprefix("policy:")
    policies = {}
    for kind in ("linear", "fnn"):
        folder = runs.pars_folder(kind, runs.directions)
        if runs.pars_finished(folder):
            policies[f"pars_{kind}"] = str(runs.best_seed_folder(folder))
    return {**policies, "pars_lstm": lstm}


def tab3(runs: Runs, path) -> dict:
    """Decision latency of the trained PARS policies (their own widths and inputs), UVLS and
    the MPC (`experiments.bench.latency`)."""
    from experiments.bench.controller_latency import bench_study

    plt = _plt()
    s = runs.settings
    policies = _trained_policies(runs)
    mpc = None if "mpc" in s.skip_baselines else s.mpc
    rows = bench_study(str(runs.study_file), batch=8, calls=s.latency_calls, mpc=mpc,
                       mpc_batch=2, policies=policies)["controllers"]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    labels = [r["controller"] for r in rows]
    seconds_per_decision = [r["one_task_ms"] / 1e3 for r in rows]
    ax.barh(labels, seconds_per_decision)
    ax.set_xscale("log")  # bars from a decade below the fastest, so their lengths compare
    ax.set_xlim(left=10.0 ** (np.floor(np.log10(min(seconds_per_decision))) - 1))
    ax.set_xlabel("seconds per decision, one task")
    ax.set_title(f"Decision time, {runs.study.name} ({jax.devices()[0].platform})")
    _save(fig, path)
    by_label = {r["controller"]: r for r in rows}
    seconds = {"PARS LSTM": next(r for r in rows if r["controller"].startswith("pars_lstm")),
               "MPC": next((r for r in rows if r["controller"].startswith("mpc")), None)}
    numbers = {f"{k}, s per decision": float(f"{r['one_task_ms'] / 1e3:.3g}")
               for k, r in seconds.items() if r is not None}
    numbers.update({f"{k}, ms per decision (one task)": v["one_task_ms"]
                    for k, v in by_label.items()})
    return {"numbers": numbers, "settings": f"trained policies {policies}; one task, median "
            f"of {s.latency_calls} calls on {jax.devices()[0].platform}"
            + ("" if mpc is None else f"; MPC options {mpc or 'defaults'}") + _skipped(runs)}


def generalisation(runs: Runs, path) -> dict:
    """The main policy against UVLS on the study's "generalisation" task set (operating
    points it never trained on): the share of tasks it wins, overall and per point."""
    if "generalisation" not in runs.study.definition.tasks:
        raise NotApplicable(f"study {runs.study.name!r} has no [tasks.generalisation] set")
    plt = _plt()
    pars = runs.evaluation(runs.main_policy(), "generalisation")
    uvls = runs.evaluation("uvls", "generalisation")
    shares = claims.difference_shares(pars, uvls)
    ours, theirs = claims.paired_rewards(pars, uvls)
    labels = [t["operating_point"] for t in pars["tasks"]]
    points = list(dict.fromkeys(labels))
    per_point = {p: float(np.mean([o > u for o, u, q in zip(ours, theirs, labels) if q == p]))
                 for p in points}
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(points) + 1.5))
    ax.barh(points, [100 * v for v in per_point.values()])
    ax.set_xlim(0, 100)
    ax.set_xlabel("tasks where PARS earns more than UVLS (%)")
    ax.set_title(f"{runs.study.name}: PARS against UVLS on untrained operating points")
    ax.tick_params(axis="y", labelsize=7)
    _save(fig, path)
    numbers = {"tasks": len(ours), "operating points": len(points),
               "PARS better than UVLS on": shares["better"],
               "PARS at least as good as UVLS on": shares["at least as good"],
               "PARS fails on": claims.failures(pars), "UVLS fails on": claims.failures(uvls),
               "mean reward, PARS": round(float(ours.mean()), 1),
               "mean reward, UVLS": round(float(theirs.mean()), 1)}
    numbers.update({f"PARS better than UVLS at {p}": claims.percent(v)
                    for p, v in per_point.items()})
    return {"numbers": numbers, "settings": f"{len(ours)} tasks of the generalisation set "
            f"of {runs.study.name} (points {points}); PARS {pars['controller']}"}


class NotApplicable(Exception):
    """An experiment the study cannot run (it lacks what the experiment needs)."""


EXPERIMENTS = {"fig6a": fig6a, "fig6b": fig6b, "fig7": fig7, "fig8": fig8, "fig9": fig9,
               "fig10_11": fig10_11, "fig12": fig12, "tab3": tab3, "fig13": fig13,
               "generalisation": generalisation}
