"""The PARS study's published networks (RLGC `trainedModels`) as a controller: "rlgc:FILE.npz".

The format (../shared/reference/rlgc-policies/README.md; the code that wrote and ran them:
pnnl/HADREC src/policy_LSTM.py, src/ars_rand_faultandpf_cases_LSTM_gridpack_general.py):
`np.load(FILE, allow_pickle=True)["arr_0"]` is [w, obs_mean, obs_std, ...] (a pickled object
array, so read only files you trust). The network
sees x = (ob − obs_mean) / (obs_std + 1e-8); no layer has a bias; tanh follows every layer:

    linear  w (actions, inputs):  t = tanh(w x)
    FNN     w flat, layers [inputs, H, H, actions]: for each pair (a, b) the next a·b
            entries, row-major, are a (b, a) matrix M; y = tanh(M y)
    LSTM    w flat: four (inputs + H, H) matrices, row-major, forget, input, cell, output;
            z = [h, x]; f = σ(z Wf), i = σ(z Wi), g = tanh(z Wc), c = f·c + i·g,
            o = σ(z Wo), h = o·tanh(c); then dense layers [H, H, actions] as the FNN's.
            h = c = 0 at the start of an episode.

t ∈ [−1, 1] maps linearly onto the layout's action range: a = low + (t + 1)/2·(high − low).
What the network observes and acts on is its `baselines.rlgc_layouts.ObservationLayout`; its
inputs are `history` such observations stacked, oldest first, as the environment stacks
them. Nothing in the file names its kind or sizes: `read_policy` finds the one published
layout, kind and width H whose sizes give the file's w and obs_mean (a params.json beside
the file, where RLGC has one, must agree). `training_log` reads the log.txt beside it.
"""
from __future__ import annotations

import dataclasses
import json
import pickle
import re
import zipfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from baselines.rlgc_layouts import PUBLISHED, ObservationLayout
from jaxgrid.env import LoadSheddingEnv

STD_EPS = 1e-8  # the normaliser's (ob − mean) / (std + 1e-8)
KINDS = {"linear": "linear", "nonlinear": "fnn", "LSTM": "lstm"}  # params.json policy_type
# The 9 per-task rewards of a 39-bus log.txt: the task file's faultBusCandidates ×
# faultDurationCandidates, bus first (HADREC's PF_FAULT_CASES_ALL), all starting at 1.0 s.
LOG_TASKS = tuple((bus, duration) for bus in (4, 15, 21) for duration in (0.0, 0.05, 0.08))
LOG_FAULT_START = 1.0


@dataclasses.dataclass(frozen=True)
class RlgcNetwork:
    """A published network's architecture (static).

    Attributes:
      kind: "linear" | "fnn" | "lstm".  inputs, actions: vector lengths.
      hidden: the two widths (H, H) of the FNN's tanh layers, or the LSTM's units and its
        dense layer; () for linear.
    """

    kind: str
    inputs: int
    actions: int
    hidden: tuple[int, ...] = ()

    def shapes(self) -> tuple[tuple[int, int], ...]:
        """The matrices in w's order: the LSTM's four gates (inputs + H, H), then the
        dense layers (b, a)."""
        if self.kind == "linear":
            return ((self.actions, self.inputs),)
        gates = ((self.inputs + self.hidden[0], self.hidden[0]),) * 4 \
            if self.kind == "lstm" else ()
        widths = (self.hidden if self.kind == "lstm" else (self.inputs, *self.hidden)) \
            + (self.actions,)
        return gates + tuple((b, a) for a, b in zip(widths, widths[1:]))

    @property
    def size(self) -> int:
        """Entries of w."""
        return sum(a * b for a, b in self.shapes())

    def matrices(self, w: np.ndarray) -> tuple[np.ndarray, ...]:
        """w split into `shapes()` (each row-major)."""
        flat, out, start = np.ravel(w), [], 0
        for shape in self.shapes():
            out.append(flat[start:start + shape[0] * shape[1]].reshape(shape))
            start += shape[0] * shape[1]
        return tuple(out)

    def initial_carry(self):
        """(h, c) zeros (H,) for the LSTM, float32; None otherwise."""
        return (jnp.zeros(self.hidden[0]),) * 2 if self.kind == "lstm" else None

    def forward(self, matrices, x, carry):
        """(t (actions,) in [−1, 1], carry) for a normalised input x (inputs,)."""
        dense = matrices
        if self.kind == "lstm":
            (wf, wi, wc, wo), dense = matrices[:4], matrices[4:]
            h, c = carry
            z = jnp.concatenate([h, x])
            c = jax.nn.sigmoid(z @ wf) * c + jax.nn.sigmoid(z @ wi) * jnp.tanh(z @ wc)
            h = jax.nn.sigmoid(z @ wo) * jnp.tanh(c)
            x, carry = h, (h, c)
        for m in dense:
            x = jnp.tanh(m @ x)
        return x, carry


def networks_of_size(w_shape: tuple[int, ...], inputs: int, actions: int) -> list[RlgcNetwork]:
    """The networks of `inputs` and `actions` whose w has shape `w_shape`: linear for a
    (actions, inputs) matrix; FNN and LSTM of equal widths (H, H) for a flat w."""
    if len(w_shape) == 2:
        return [RlgcNetwork("linear", inputs, actions)] if w_shape == (actions, inputs) else []
    if len(w_shape) != 1:
        return []
    found = []
    for kind in ("fnn", "lstm"):
        width = 1
        while (network := RlgcNetwork(kind, inputs, actions, (width, width))).size < w_shape[0]:
            width += 1
        if network.size == w_shape[0]:
            found.append(network)
    return found


@dataclasses.dataclass(frozen=True)
class RlgcPolicy:
    """A published policy file, read.

    Attributes:
      path: the file.  network: its architecture.  layout: what it observes and acts on.
      history: observations stacked in its input (inputs = history × layout.frame_size).
    """

    path: str
    network: RlgcNetwork
    layout: ObservationLayout
    history: int


def read_policy(path: str | Path):
    """(RlgcPolicy, params {"matrices", "mean", "std"} float32) of a published file.
    ValueError naming the file: not readable as the format, sizes that fit no published
    layout and network (or more than one), or a params.json beside it that disagrees."""
    path = Path(path)
    w, mean, std = _arrays(path)
    fits = [RlgcPolicy(str(path), network, layout, mean.size // layout.frame_size)
            for layout in PUBLISHED if mean.size % layout.frame_size == 0
            for network in networks_of_size(w.shape, mean.size, len(layout.action_buses))]
    what = f"{path}: w of shape {w.shape} with {mean.size} inputs"
    if not fits:
        known = "; ".join(f"{lay.name}: inputs k × {lay.frame_size}, "
                          f"{len(lay.action_buses)} actions" for lay in PUBLISHED)
        raise ValueError(f"{what} fits none of the published layouts ({known}) and networks "
                         "(linear (actions, inputs); FNN [inputs, H, H, actions]; LSTM of H "
                         "units, then [H, H, actions])")
    if len(fits) > 1:
        raise ValueError(f"{what} fits more than one published layout and network: " + ", ".join(
            f"{p.layout.name} {p.network.kind} {p.network.hidden}" for p in fits))
    policy = fits[0]
    _check_params_json(policy)
    params = {"matrices": tuple(np.asarray(m, np.float32)
                                for m in policy.network.matrices(w)),
              "mean": np.asarray(mean, np.float32), "std": np.asarray(std, np.float32)}
    return policy, params


def _arrays(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(w, obs_mean, obs_std) float64 of a published file; ValueError naming it."""
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    form = "an npz whose arr_0 is [w, obs_mean, obs_std, ...]"
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path}: not a published policy file ({form})")
    try:
        with np.load(path, allow_pickle=True) as data:
            saved = data["arr_0"]
    except (KeyError, ValueError, EOFError, pickle.UnpicklingError) as err:
        raise ValueError(f"{path}: not a published policy file ({form}): {err!r}") from None
    if saved.ndim != 1 or saved.shape[0] < 3:
        raise ValueError(f"{path}: arr_0 has shape {saved.shape}; a published policy's is "
                         "[w, obs_mean, obs_std, ...]")
    try:
        w, mean, std = (np.asarray(a, np.float64) for a in saved[:3])
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: w, obs_mean, obs_std are not numeric arrays: {err}") from None
    if mean.ndim != 1 or mean.size == 0 or std.shape != mean.shape:
        raise ValueError(f"{path}: obs_mean {mean.shape} and obs_std {std.shape} must be one "
                         "vector each, of the same length, not empty")
    if not all(np.isfinite(a).all() for a in (w, mean, std)) or (std < 0).any():
        raise ValueError(f"{path}: w, obs_mean and obs_std must be finite and obs_std >= 0")
    return w, mean, std


def _check_params_json(policy: RlgcPolicy) -> None:
    """ValueError if the params.json beside the file names another kind or widths."""
    params_file = Path(policy.path).with_name("params.json")
    if not params_file.is_file():
        return
    try:
        params = json.loads(params_file.read_text())
    except ValueError as err:
        raise ValueError(f"{params_file}: not JSON: {err}") from None
    kind = KINDS.get(params.get("policy_type"))
    widths = tuple(params.get("policy_network_size", ()))
    network = policy.network
    if kind != network.kind or (kind != "linear" and widths != network.hidden):
        raise ValueError(f"{policy.path}: its w fits a {network.kind} network "
                         f"{network.hidden}, but {params_file} says policy_type "
                         f"{params.get('policy_type')!r}, policy_network_size {list(widths)}")


def rlgc_apply(policy: RlgcPolicy, env: LoadSheddingEnv):
    """policy_apply(params, obs, carry, inputs) -> (action (n_action,), carry) of `policy` on
    `env` (`inputs` unused), whose history must be policy.history: its inputs picked from
    each stacked observation, normalised, the network, t mapped onto the layout's range and
    placed at the layout's action buses (the env's other action buses shed nothing).
    ValueError naming the file if the env does not observe or act on the layout's buses."""
    if env.config.history != policy.history:
        raise ValueError(f"{policy.path} stacks {policy.history} observations; the "
                         f"environment {env.config.history}")
    picks, slots = policy.layout.indices(env.config, policy.path)
    return _Apply(policy.network, picks, slots, len(env.action_slots), env.obs_size,
                  policy.layout.action_low, policy.layout.action_high)


@dataclasses.dataclass(frozen=True)
class _Apply:
    """`rlgc_apply`'s function; equal for equal structure, so evaluations of files of one
    architecture share their compilation (`jaxgrid.problem.play_specs` caches by it)."""

    network: RlgcNetwork
    picks: tuple[int, ...]
    slots: tuple[int, ...]
    n_action: int
    obs_size: int
    low: float
    high: float

    def __call__(self, params, obs, carry, inputs):
        x = obs.reshape(-1, self.obs_size)[:, np.array(self.picks)].reshape(-1)
        x = (x - params["mean"]) / (params["std"] + STD_EPS)
        t, carry = self.network.forward(params["matrices"], x, carry)
        action = self.low + (t + 1.0) * (0.5 * (self.high - self.low))
        return jnp.zeros(self.n_action, action.dtype).at[np.array(self.slots)].set(action), carry


@dataclasses.dataclass(frozen=True)
class TrainingLog:
    """The log.txt row of a published file's iteration.

    Attributes:
      path: the log.  iteration: the file's (policy_plusN.npz).
      rewards: {(fault bus, fault duration s): reward} of the 9 training tasks, all at 1.0 s.
    """

    path: str
    iteration: int
    rewards: dict

    def reward(self, fault_bus: int, fault_duration: float, fault_start: float):
        """The logged reward of a task, or None where the log has none."""
        if abs(fault_start - LOG_FAULT_START) > 1e-9:
            return None
        return next((r for (bus, duration), r in self.rewards.items()
                     if bus == fault_bus and abs(duration - fault_duration) < 1e-9), None)


def training_log(path: str | Path) -> TrainingLog | None:
    """The log.txt beside a published file at the file's iteration (policy_plusN: N), or
    None if there is no log or the name gives no iteration. ValueError naming the log if it
    has no row of that iteration or not the 9 per-task rewards."""
    path = Path(path)
    log = path.with_name("log.txt")
    found = re.fullmatch(r"policy_plus(\d+)\.npz", path.name)
    if not (log.is_file() and found):
        return None
    header, *rows = [line.split("\t") for line in log.read_text().splitlines() if line]
    columns = [i for i, name in enumerate(header) if name.startswith("reward ")]
    if len(columns) != len(LOG_TASKS) or "Iteration" not in header:
        raise ValueError(f"{log}: expected the columns Iteration and {len(LOG_TASKS)} "
                         f"'reward k:' (the 39-bus training tasks), found {header}")
    iteration = int(found[1])
    try:
        table = np.array(rows, float)
    except ValueError as err:
        raise ValueError(f"{log}: not a table of numbers under its header: {err}") from None
    match = table[table[:, header.index("Iteration")] == iteration]
    if not len(match):
        raise ValueError(f"{log}: no row of iteration {iteration} ({path.name})")
    return TrainingLog(str(log), iteration,
                       {task: float(match[0, i]) for task, i in zip(LOG_TASKS, columns)})
