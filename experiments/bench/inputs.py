"""The reference inputs the benchmarks read: the PNNL and ACTIVSg cases beside the repository
(`SHARED`, read in place)."""
from __future__ import annotations

from pathlib import Path

SHARED = Path(__file__).resolve().parents[3] / "shared" / "cases"

