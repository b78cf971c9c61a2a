"""PSS/E dynamics data records: `DyrRecord` (one model record), `DyrData` (a file's records).

The fields follow the PSS/E Program Operation Manual's DYR layout (activity DYRE), as the
reader's docstring describes it.

The DYR reader (`jaxgrid.io.dyr`) returns them, `jaxgrid.cases` builds them in code, and the
device models (`jaxgrid.models`) and `jaxgrid.compile` read them; keeping them here lets the
models know the record without the parser.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass


@dataclass(frozen=True)
class DyrRecord:
    """One dynamic model record.

    `record_type` is the second field: the model itself for ordinary records,
    'USRLOD'/'USRMDL' for user-written ones. `icons` and `header` are empty for
    ordinary records; a quoted ICON is kept as a string.
    """

    model: str
    bus: int
    device_id: str
    cons: tuple[float, ...]
    icons: tuple[int | str, ...]
    header: tuple[int, ...]
    record_type: str
    line: int
    source: str


@dataclass(frozen=True)
class DyrData:
    """All records of one DYR file, in file order."""

    source: str
    records: tuple[DyrRecord, ...]
    unsupported: dict[str, int]

    def by_model(self, name: str) -> tuple[DyrRecord, ...]:
        """Records whose model is `name` (case-insensitive)."""
        name = name.upper()
        return tuple(r for r in self.records if r.model == name)

    def counts(self) -> dict[str, int]:
        """Number of records per model, in order of first appearance."""
        return dict(Counter(r.model for r in self.records))
