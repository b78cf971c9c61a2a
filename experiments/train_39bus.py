"""PARS on the IEEE 39-bus FIDVR case with the study's defaults (LSTM [32, 32], N = 16,
b = 8, α = 1, ν = 2, ε = 0.99). See experiments/train.py for the flags and outputs."""
import sys

from experiments.train import DEFAULTS as PLAIN
from experiments.train import main

DEFAULTS = {**PLAIN, "study": "ieee39_fidvr", "policy": "lstm", "hidden": "32,32",
            "directions": 16, "top": 8, "decay": 0.99, "iterations": 200}

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:], DEFAULTS))
