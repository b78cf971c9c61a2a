"""The reproduction of the PARS paper: `harness` (the command and REPORT.md), `runs` (the
trainings and evaluations, cached by their inputs), `figures` (the experiments, named after
the paper's figures and tables) and `claims` (the paper's side claims, computed)."""
