"""Property-based fuzzing of every reader and study value (Hypothesis, derandomized).

Each input kind of `experiments.diagnostics.fuzz_inputs` (the PNNL 39-bus RAW v30 and v33, its
DYR, task and simulation JSON, two study TOMLs) is mutated JAXGRID_FUZZ_EXAMPLES times
(default 60; a third for the kinds whose mutants build a study). Property: every mutant gives a clear error
that names its file (a study file: and its table), or a result with only finite values, no
repeated or empty list setting and no ignored setting; never a bare exception, never silent
garbage, never a hang. `python -m experiments.diagnostics.fuzz_inputs --examples N --seed S` runs a
campaign.
"""
from __future__ import annotations

import os

import pytest

from experiments.diagnostics.fuzz_inputs import examples_for, kinds, run_kind

EXAMPLES = int(os.environ.get("JAXGRID_FUZZ_EXAMPLES", "60"))


@pytest.mark.parametrize("kind", list(kinds()))
def test_mutants_give_a_clear_error_or_a_finite_result(kind):
    failures = []

    def record(outcome, description, detail):
        if outcome not in ("valid", "clear error"):
            failures.append(f"{outcome}: {description}: {detail}")

    run_kind(kind, examples_for(kind, EXAMPLES), record)
    assert not failures, "\n".join(failures[:10])
