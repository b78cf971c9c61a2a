"""The experiments of `experiments.reproduce`, named after the PARS paper's figures and tables.

Each experiment takes the `Runs` of a reproduction, gets the runs it needs from it (cached),
writes its figure `OUT/<id>.png`, and returns its numbers: {"numbers": {quantity: ours},
"settings": what ran}. `PAPER` holds, per experiment, its title, the paper's case and
settings, and the paper's values for the same quantities (from the paper's text, figures
and tables; "≈" marks values read off a figure).
"""
from __future__ import annotations

import jax
import numpy as np

from experiments.repro_runs import Runs, convergence_iteration, metrics_rows
from experiments.train import smoothed

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
             "values": {"reward, PARS": -94.09, "reward, UVLS": -2367.21}},
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
                         "PARS better than PPO on": "95.29 %"}},
    "tab3": {"title": "Decision time per control step", "case": "IEEE 300-bus",
             "settings": "PARS policy vs trajectory-sensitivity MPC",
             "values": {"PARS LSTM, s per decision": 0.72, "MPC, s per decision": 63.31}},
    "fig13": {"title": "300-bus case study: fault at bus 23, 0.1 s; bus-33 voltage, MW shed",
              "case": "IEEE 300-bus", "settings": "fault at bus 23 for 0.1 s",
              "values": {"reward, PARS": -823.6, "reward, MPC": -876.6, "reward, PPO": -927.3,
                         "reward, UVLS": -21901.8}},
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
    per run: best moving-average reward, convergence iteration, seconds per iteration."""
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
        numbers[f"converged at iteration, {label}"] = convergence_iteration(
            it, mean, min(window, len(mean)))
        wall = np.diff(curves["wall_s"], prepend=0.0)  # per iteration; the first compiles
        numbers[f"s per iteration ({_seeds(reward.shape[0])} in one program), {label}"] = round(
            float(wall[1:].mean() if len(wall) > 1 else wall[0]), 2)
    ax.set_xlabel("iteration")
    ax.set_ylabel("reward per episode (mean of the perturbed rollouts)")
    ax.set_title(f"{title} — {runs.study.name}, mean ± std over {_seeds(runs.settings.seeds)}")
    ax.legend()
    ax.grid(alpha=0.3)
    _save(fig, path)
    return numbers


def fig6a(runs: Runs, path) -> dict:
    n = runs.settings.directions
    numbers = _curves(runs, [(kind, n, kind) for kind in ("linear", "fnn", "lstm")],
                      f"PARS policies, N = {n}", path)
    return {"numbers": numbers, "settings": f"N = {n}, b = {max(1, n // 2)}, "
            f"m = {runs.settings.tasks_per_iteration}, {_seeds(runs.settings.seeds)}, "
            f"{runs.settings.iterations} iterations"}


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
    return {"numbers": numbers, "settings": f"LSTM, N = {s.directions}, m = "
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


def _pars_policy(runs: Runs, directions: int) -> str:
    """The given PARS policy, or the best seed of the LSTM run with N = directions."""
    if runs.settings.policy:
        return f"policy:{runs.settings.policy}"
    return runs.best_seed(runs.pars("lstm", directions))


def fig8(runs: Runs, path) -> dict:
    policy = _pars_policy(runs, runs.settings.directions)
    return _case_study(runs, path, {"PARS": policy, "UVLS": "uvls"}, 3, 0.08, 4)


def _ppo_policy(runs: Runs) -> str:
    """The given PPO policy, or that of the first PPO training."""
    if runs.settings.ppo_policy:
        return f"ppo:{runs.settings.ppo_policy}"
    return f"ppo:{runs.ppo(0, _ppo_steps(runs)) / 'policy'}"


def _ppo_steps(runs: Runs) -> int:
    """PPO environment steps: the settings', or as many as one PARS training."""
    s = runs.settings
    if s.ppo_env_steps is not None:
        return s.ppo_env_steps
    steps = int(round(runs.study.config.episode / runs.study.config.agent_dt))
    return s.iterations * 2 * s.directions * s.tasks_per_iteration * steps


def fig13(runs: Runs, path) -> dict:
    policy = _pars_policy(runs, max(runs.settings.sweep_large))
    return _case_study(runs, path, {"PARS": policy, "MPC": "mpc", "PPO": _ppo_policy(runs),
                                    "UVLS": "uvls"}, 23, 0.1, 33)


def fig10_11(runs: Runs, path) -> dict:
    """Training reward of PARS (fig6a's LSTM run, every seed: mean over its perturbed
    rollouts) and PPO (`ppo_seeds` runs: mean return of the episodes each chunk ended)
    against wall time and environment steps."""
    plt = _plt()
    s = runs.settings
    steps = int(round(runs.study.config.episode / runs.study.config.agent_dt))
    pars = runs.pars_curves(runs.pars("lstm", s.directions))
    ppo_rows = [metrics_rows(runs.ppo(seed, _ppo_steps(runs)) / "metrics.jsonl") for seed in range(s.ppo_seeds)]
    n = min(len(rows) for rows in ppo_rows)
    ppo_reward = np.array([[r["reward_train"] if r["reward_train"] is not None else np.nan
                            for r in rows[:n]] for rows in ppo_rows], float)
    ppo_wall = np.mean([[r["wall_total_s"] for r in rows[:n]] for rows in ppo_rows], 0)
    ppo_steps = np.array([r["env_steps"] for r in ppo_rows[0][:n]])
    curves = {"PARS": (pars["wall_s"], pars["episodes"] * steps, pars["reward"]),
              "PPO": (ppo_wall, ppo_steps, ppo_reward)}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    numbers = {}
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
        numbers[f"wall s to convergence, {label}"] = (None if settled is None
                                                     else round(float(wall[settled]), 1))
        numbers[f"wall s in all, {label}"] = round(float(wall[-1]), 1)
    if None not in (numbers["wall s to convergence, PARS"], numbers["wall s to convergence, PPO"]):
        numbers["wall-time speed-up to convergence, PPO / PARS"] = round(
            numbers["wall s to convergence, PPO"] / max(numbers["wall s to convergence, PARS"],
                                                      1e-9), 2)
    axes[0].set_xlabel("wall time (s)")
    axes[1].set_xlabel("environment steps (agent steps of 0.1 s)")
    axes[0].set_ylabel("training reward per episode")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"PARS vs PPO on {runs.study.name}")
    _save(fig, path)
    return {"numbers": numbers, "settings": f"PARS LSTM N = {s.directions}, "
            f"{s.iterations} iterations × {_seeds(s.seeds)} in one program; PPO {s.ppo_seeds} "
            f"seeds × {_ppo_steps(runs)} env steps (Table II settings), one after another"}


def fig12(runs: Runs, path) -> dict:
    plt = _plt()
    pars = runs.evaluation(_pars_policy(runs, max(runs.settings.sweep_large)))
    others = {"UVLS": runs.evaluation("uvls"), "MPC": runs.evaluation("mpc"),
              "PPO": runs.evaluation(_ppo_policy(runs))}
    ours = np.array([t["reward"] for t in pars["tasks"]])
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    numbers = {"test tasks": len(ours)}
    for ax, (label, result) in zip(axes, others.items()):
        difference = ours - np.array([t["reward"] for t in result["tasks"]])
        better = float(np.mean(difference > 0))
        numbers[f"PARS better than {label} on"] = f"{100 * better:.2f} %"
        numbers[f"PARS at least as good as {label} on"] = (
            f"{100 * float(np.mean(difference >= 0)):.2f} %")
        numbers[f"mean reward, {label}"] = round(result["summary"]["mean_reward"], 1)
        ax.hist(difference, bins=20)
        ax.axvline(0, color="k", lw=1)
        ax.set_title(f"PARS − {label}: PARS better on {100 * better:.1f} %")
        ax.set_xlabel("reward difference per task")
    numbers["mean reward, PARS"] = round(pars["summary"]["mean_reward"], 1)
    axes[0].set_ylabel("test tasks")
    _save(fig, path)
    return {"numbers": numbers, "settings": f"{len(ours)} test tasks of {runs.study.name}; "
            f"PARS {pars['controller']}, PPO {others['PPO']['controller']}"}


def tab3(runs: Runs, path) -> dict:
    """Decision latency of the PARS policies and the MPC (`experiments.bench_latency`)."""
    from experiments.bench_latency import bench_study

    plt = _plt()
    s = runs.settings
    rows = bench_study(str(runs.study_file), batch=8, calls=s.latency_calls, mpc=s.mpc,
                       mpc_batch=2)["controllers"]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    labels = [r["controller"] for r in rows]
    ax.barh(labels, [r["one_task_ms"] / 1e3 for r in rows])
    ax.set_xscale("log")
    ax.set_xlabel("seconds per decision, one task")
    ax.set_title(f"Decision time, {runs.study.name} ({jax.devices()[0].platform})")
    _save(fig, path)
    by_label = {r["controller"]: r for r in rows}
    lstm = next(r for r in rows if r["controller"].startswith("pars_lstm"))
    mpc = next(r for r in rows if r["controller"].startswith("mpc"))
    numbers = {"PARS LSTM, s per decision": float(f"{lstm['one_task_ms'] / 1e3:.3g}"),
               "MPC, s per decision": float(f"{mpc['one_task_ms'] / 1e3:.3g}")}
    numbers.update({f"{k}, ms per decision (one task)": v["one_task_ms"]
                    for k, v in by_label.items()})
    return {"numbers": numbers, "settings": f"one task, median of {s.latency_calls} calls "
            f"on {jax.devices()[0].platform}; MPC options {s.mpc or 'defaults'}"}


EXPERIMENTS = {"fig6a": fig6a, "fig6b": fig6b, "fig7": fig7, "fig8": fig8, "fig9": fig9,
               "fig10_11": fig10_11, "fig12": fig12, "tab3": tab3, "fig13": fig13}
