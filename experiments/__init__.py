"""Command-line experiments (`python -m experiments.<name>`) and benchmarks
(`python -m experiments.bench.<name>`)."""
