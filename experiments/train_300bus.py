"""PARS on the IEEE 300-bus FIDVR case with the study's defaults (LSTM [64, 64], N = 128,
b = 64, α = 1, ν = 2, ε = 0.996). The m tasks run one after another (task_batch 1: 256
rollouts per batch, and a task's batch stops once all its episodes have failed; measured
on 2 CPU devices 1.17× faster per iteration at θ = 0, 2.4× after the first update). See experiments/train.py for the
flags and outputs."""
import sys

from experiments.train import DEFAULTS as PLAIN
from experiments.train import main

DEFAULTS = {**PLAIN, "study": "ieee300_fidvr", "policy": "lstm", "hidden": "64,64",
            "directions": 128, "top": 64, "decay": 0.996, "iterations": 500,
            "task_batch": 1}

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:], DEFAULTS))
