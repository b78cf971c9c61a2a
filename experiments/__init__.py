"""Command-line experiments and benchmarks (python -m experiments.<name>)."""
