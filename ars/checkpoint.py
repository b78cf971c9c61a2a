"""Checkpoints (orbax-checkpoint) and saved policies.

A checkpoint holds the TrainState (θ, normaliser, PRNG key, iteration, α, ν) and a JSON
part (config, metrics so far). A saved policy is a folder of `policy.json` ("spec": the
architecture, and whatever the trainer adds; other learners add "kind") + `policy.npz` (the
arrays: θ, observation mean, std and count for PARS), loadable without orbax. A training
can start from a saved policy (`warm_start`).
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import jax
import numpy as np
import orbax.checkpoint as ocp

from ars.iteration import TrainState
from ars.policies import Policy, PolicySpec


def manager(directory: str | Path, every: int) -> ocp.CheckpointManager:
    """A manager that saves every `every` iterations (and when forced) and keeps the last 3."""
    options = ocp.CheckpointManagerOptions(save_interval_steps=every, max_to_keep=3)
    return ocp.CheckpointManager(Path(directory).absolute(), options=options)


def save(mgr: ocp.CheckpointManager, state: TrainState, meta: dict, force: bool = False,
         step: int | None = None) -> None:
    """Save `state` (any pytree) and the JSON-able `meta` at `step` (default
    state.iteration), if due or forced."""
    step = int(state.iteration) if step is None else int(step)
    mgr.save(step, args=ocp.args.Composite(
        state=ocp.args.StandardSave(state), meta=ocp.args.JsonSave(meta)), force=force)
    mgr.wait_until_finished()


def restore_latest(mgr: ocp.CheckpointManager, template: TrainState):
    """(state, meta) of the latest checkpoint, or None if there is none.

    The state comes back in host memory (numpy), so `make_iteration` can place it on a
    mesh that spans several processes.
    """
    step = mgr.latest_step()
    if step is None:
        return None
    out = mgr.restore(step, args=ocp.args.Composite(
        state=ocp.args.StandardRestore(template), meta=ocp.args.JsonRestore()))
    return jax.device_get(out.state), out.meta


def save_policy(directory: str | Path, spec: PolicySpec, state: TrainState, extra: dict) -> None:
    """Write policy.json (spec + extra) and policy.npz (theta, mean, std, and count: the
    observations the statistics hold) into `directory`."""
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "policy.json").write_text(json.dumps(
        {"spec": dataclasses.asdict(spec), **extra}, indent=1))
    np.savez(folder / "policy.npz", theta=np.asarray(state.theta),
             mean=np.asarray(state.stats.mean), std=np.asarray(state.stats.std),
             count=np.asarray(state.stats.count))


def read_policy_info(directory: str | Path) -> dict:
    """policy.json of a saved policy folder; ValueError if policy.json or policy.npz is
    missing."""
    folder = Path(directory)
    for name in ("policy.json", "policy.npz"):
        if not (folder / name).is_file():
            raise ValueError(f"{folder}: no {name} (not a saved policy folder)")
    return json.loads((folder / "policy.json").read_text())


def load_policy(directory: str | Path):
    """(Policy, (θ, mean, std), info dict) from a folder written by `save_policy`."""
    folder = Path(directory)
    info = read_policy_info(folder)
    if info.get("kind") is not None:  # other learners' policies name their kind
        raise ValueError(f"{folder}: a {info['kind']!r} policy, not a PARS one")
    spec = info["spec"]
    policy = Policy(PolicySpec(**{**spec, "hidden": tuple(spec["hidden"])}))
    arrays = np.load(folder / "policy.npz")
    if arrays["theta"].shape != (policy.size,):
        raise ValueError(f"{folder}: theta has {arrays['theta'].shape} values, the "
                         f"{spec['kind']} policy needs {policy.size}")
    return policy, (arrays["theta"], arrays["mean"], arrays["std"]), info


def metrics_rows(path: Path) -> list[dict]:
    """The lines of a run's metrics.jsonl (`ars.train`), [] if there is none yet."""
    return [json.loads(line) for line in path.read_text().splitlines()] if path.is_file() else []


def warm_start(state: TrainState, directory: str | Path, spec: PolicySpec) -> TrainState:
    """`state` with θ and the observation statistics of the saved PARS policy in `directory`
    (with a seed axis, every seed starts from it): a training that fine-tunes a trained policy
    under other settings. The statistics keep their weight (the observations the policy's run
    had seen), so the inputs stay scaled as the policy was trained; a feature its run saw as
    constant (std 1 saved) is held at mean ± 1. The output range may differ (a fine-tune
    under another `ars.train.TrainConfig.max_request`: the network is kept, its outputs
    scale to the new range); ValueError if the rest of the saved spec is not `spec`."""
    policy, (theta, mean, std), info = load_policy(directory)
    ranged = dataclasses.replace(policy.spec, action_low=spec.action_low,
                                 action_high=spec.action_high)
    if ranged != spec:
        raise ValueError(f"--init-policy {directory}: its policy is {policy.spec}, the "
                         f"training's is {spec} (same kind, sizes, widths and input options)")
    count = np.float32(observations_seen(Path(directory), info))
    stats = state.stats.replace(count=count, mean=mean, m2=np.square(std) * count)

    def fill(template, value):  # onto the state's shape: a seed axis, where there is one
        return jax.numpy.broadcast_to(jax.numpy.asarray(value, template.dtype), template.shape)

    return state.replace(theta=fill(state.theta, theta),
                         stats=jax.tree.map(fill, state.stats, stats))


def observations_seen(folder: Path, info: dict) -> float:
    """How many observations a saved policy's statistics hold: policy.npz's count, or for a
    policy saved before the count was kept, its run's env_steps at the policy's iteration
    (metrics.jsonl of the run folder: the parent of policy/, of policies/NNNNN/ or of a
    seed's folder); ValueError if neither is there."""
    arrays = np.load(folder / "policy.npz")
    if "count" in arrays:
        return float(arrays["count"])
    for run in (folder.parent, folder.parent.parent):
        steps = next((m.get("env_steps") for m in metrics_rows(run / "metrics.jsonl")
                      if m["iteration"] == info.get("iteration")), None)
        if isinstance(steps, list):  # a run of several seeds: this policy's
            steps = steps[info["seed"] - info["config"]["seed"]]
        if steps:
            return float(steps)
    raise ValueError(f"{folder}: policy.npz has no count and no metrics.jsonl beside it gives "
                     f"env_steps at iteration {info.get('iteration')}: the observations its "
                     "statistics hold are unknown")
