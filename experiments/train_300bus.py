"""PARS on the built-in IEEE 300-bus FIDVR study with the paper's hyper-parameters for its size
(LSTM [64, 64], N = 128, b = 64, α = 1, ν = 2, ε = 0.996, 500 iterations). The flags and
outputs are experiments.train's."""
import sys

from experiments.common.pars_command import run


def main(argv: list[str] | None = None) -> int:
    return run(argv, "train_300bus")


if __name__ == "__main__":
    sys.exit(main())
