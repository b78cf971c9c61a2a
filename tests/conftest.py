"""Shared test setup: two CPU devices for sharding tests, paths to reference data.

XLA_FLAGS must be set before JAX is imported anywhere, hence at the top here.
"""
import os

os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                           + " --xla_force_host_platform_device_count=2").strip()

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED_CASES = REPO.parent / "shared" / "cases"


def andes_cases_dir() -> Path:
    """Folder of the PSS/E test files bundled with the andes package (a test dependency)."""
    import importlib.util

    spec = importlib.util.find_spec("andes")
    assert spec is not None and spec.origin, "andes is a test dependency: pip install -e '.[test]'"
    return Path(spec.origin).parent / "cases"


@pytest.fixture(scope="session")
def shared_cases() -> Path:
    """../shared/cases, the PNNL reference inputs (read in place, never copied)."""
    assert SHARED_CASES.is_dir(), f"reference cases not found at {SHARED_CASES}"
    return SHARED_CASES
