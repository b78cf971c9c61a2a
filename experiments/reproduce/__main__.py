"""`python -m experiments.reproduce`: the PARS paper's experiments (`harness` says what)."""
import sys

from experiments.reproduce.harness import main

sys.exit(main())
