"""PARS on the IEEE 39-bus FIDVR case with the paper's hyper-parameters (LSTM [32, 32],
N = 16, b = 8, α = 1, ν = 2, ε = 0.99): `experiments.train.PRESETS["train_39bus"]`. See
experiments/train.py for the flags and outputs."""
import sys

from experiments.train import PRESETS, main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:], PRESETS["train_39bus"]))
