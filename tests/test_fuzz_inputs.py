"""Property-based fuzzing of every reader and study value (Hypothesis, derandomized).

Each input kind of `experiments.fuzz_inputs` (the PNNL 39-bus RAW v30 and v33, its DYR, task
and simulation JSON, a study TOML) is mutated JAXGRID_FUZZ_EXAMPLES times (default 60; the
study TOML gets a tenth, as each valid mutant compiles). Property: every mutant gives a clear
error that names its file, or a result with only finite values; never a bare exception,
never silent garbage. `python -m experiments.fuzz_inputs --examples N` runs a longer profile.
"""
from __future__ import annotations

import os

import pytest

from experiments.fuzz_inputs import examples_for, kinds, run_kind

EXAMPLES = int(os.environ.get("JAXGRID_FUZZ_EXAMPLES", "60"))


@pytest.mark.parametrize("kind", list(kinds()))
def test_mutants_give_a_clear_error_or_a_finite_result(kind):
    failures = []

    def record(outcome, description, detail):
        if outcome not in ("valid", "clear error"):
            failures.append(f"{outcome}: {description}: {detail}")

    run_kind(kind, examples_for(kind, EXAMPLES), record)
    assert not failures, "\n".join(failures[:10])
