"""Diagnostics of the simulator and its inputs, each a command: the step-size study
(`step_accuracy`), FIDVR trajectory plots (`plot_fidvr`) and the input fuzz campaign
(`fuzz_inputs`)."""
