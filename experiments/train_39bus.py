"""PARS on the built-in IEEE 39-bus FIDVR study with the paper's hyper-parameters for its size
(LSTM [32, 32], N = 16, b = 8, α = 1, ν = 2, ε = 0.99, 200 iterations). The flags and outputs
are experiments.train's."""
import sys

from experiments.common.pars_command import run


def main(argv: list[str] | None = None) -> int:
    return run(argv, "train_39bus")


if __name__ == "__main__":
    sys.exit(main())
