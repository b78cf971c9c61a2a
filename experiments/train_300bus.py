"""PARS on the IEEE 300-bus FIDVR case with the paper's hyper-parameters (LSTM [64, 64],
N = 128, b = 64, α = 1, ν = 2, ε = 0.996, the tasks one after another):
`experiments.train.PRESETS["train_300bus"]`. See experiments/train.py for the flags and
outputs."""
import sys

from experiments.train import PRESETS, main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:], PRESETS["train_300bus"]))
