"""Bus references as the PNNL study files write them, resolved to bus numbers: the one
resolver of `GridModel.bus_number_by_name` and the study's names (`jaxgrid.study.names`).

A reference is "Bus<N>" or "bus<N>" (RAW bus N), a composite load's internal bus
"Bus<N>_lowBus" / "Bus<N>_loadBus" (numbered by `jaxgrid.models.cmld_init.internal_buses`),
or a bare number (504, "504"); names are compared without case.
"""
from __future__ import annotations

import re
from collections.abc import Container, Mapping


def resolve_bus(reference, names: Mapping[str, int], numbers: Container[int], grid: str) -> int:
    """The bus number of `reference`.

    names: {lower-case name: bus number} (internal buses, and RAW buses by name).
    numbers: every bus number of the grid.  grid: how messages name it ("the case X").
    ValueError naming the reference and what is wrong with it.
    """
    text = str(reference).strip()
    number = names.get(text.lower())
    if number is not None:
        return number
    if re.fullmatch(r"bus-?\d+_\w+", text, re.IGNORECASE):
        raise ValueError(f"{reference!r}: {grid} has no such internal bus (no composite load "
                         "record there in the DYR)")
    match = re.fullmatch(r"(?:bus)?(-?\d+)", text, re.IGNORECASE)
    if not match:
        raise ValueError(f"{reference!r} is not a bus reference ('Bus<number>' or a composite "
                         "load's 'Bus<number>_loadBus')")
    if int(match.group(1)) in numbers:
        return int(match.group(1))
    raise ValueError(f"{reference!r}: {grid} has no bus {match.group(1)}")
