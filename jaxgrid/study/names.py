"""The bus names a study's files can use, resolved against its grid before compiling.

`bus_table(case, dyr)` lists the RAW buses and the composite loads' internal buses
(`jaxgrid.models.cmld_init.internal_buses`); `bus_number` resolves one PNNL reference
through `jaxgrid.busnames.resolve_bus` (the resolver `GridModel.bus_number_by_name` uses),
and `bus_scope` a PNNL "Bus" or "Zone" scope. Errors name the file, key and value.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from jaxgrid.busnames import resolve_bus
from jaxgrid.case import Case
from jaxgrid.checks import check_unique
from jaxgrid.models.cmld import COMPOSITE_LOADS
from jaxgrid.models.cmld_init import internal_buses
from jaxgrid.powerflow import bus_loads
from jaxgrid.records import DyrData


@dataclasses.dataclass(frozen=True)
class BusTable:
    """The buses a study file can name, before compiling: the RAW buses and the composite
    loads' internal buses (`jaxgrid.models.cmld_init.internal_buses`).

    Attributes:
      source: the case.  number_by_name: {lower-case name: bus number} ("bus504",
        "bus20_loadbus").  zone, base_kv, loaded: per bus number (loaded: an in-service
        RAW load, the composite loads' load buses).
    """

    source: str
    number_by_name: dict
    zone: dict
    base_kv: dict
    loaded: dict

    @property
    def numbers(self):
        """Every bus number of the grid (RAW and internal)."""
        return self.zone.keys()


def bus_table(case: Case, dyr: DyrData) -> BusTable:
    """The BusTable of `case` with the composite loads of `dyr`."""
    numbers = [int(n) for n in case.buses.number]
    names = {f"bus{n}": n for n in numbers}
    zone = dict(zip(numbers, (int(z) for z in case.buses.zone)))
    kv = dict(zip(numbers, (float(v) for v in case.buses.base_kv)))
    loaded = dict(zip(numbers, (bool(x) for x in np.abs(sum(bus_loads(case))) > 0)))
    composite = [r for r in dyr.records if r.model in COMPOSITE_LOADS]
    for record, ((low, low_name), (load, load_name)) in zip(
            composite, internal_buses(case, composite)):
        for number, name, base_kv in ((low, low_name, 0.0), (load, load_name, kv[record.bus])):
            names[name.lower()], zone[number], kv[number] = number, zone[record.bus], base_kv
            loaded[number] = number == load
    return BusTable(case.source, names, zone, kv, loaded)


def bus_number(name, buses: BusTable, source: str, key: str) -> int:
    """The number of a PNNL bus reference ("Bus504", "bus20001", "Bus20_loadBus", 504)
    read from `key` of file `source`."""
    try:
        return resolve_bus(name, buses.number_by_name, buses.numbers,
                           f"the case {buses.source}")
    except ValueError as err:
        raise ValueError(f"{source}: {key}: {err}") from None


def bus_scope(kind: str, entries, buses: BusTable, source: str, key: str,
              min_kv: float = 0.0) -> tuple[int, ...]:
    """Bus numbers of a "Bus" scope (the names) or a "Zone" scope (observations: the zones'
    buses above min_kv, kV; actions, key "actionScopeAry": the zones' buses with a load)."""
    if kind == "Bus":
        return tuple(bus_number(n, buses, source, key) for n in entries)
    zones = []
    for z in entries:
        if not str(z).strip().isdigit() or int(z) not in set(buses.zone.values()):
            raise ValueError(f"{source}: {key}: zone {z!r} is not a zone of {buses.source}")
        zones.append(int(z))
    check_unique(f"{source}: {key}", zones)
    keep = (lambda b: buses.loaded[b]) if key == "actionScopeAry" else \
        (lambda b: buses.base_kv[b] > min_kv)
    return tuple(b for b, z in buses.zone.items() if z in zones and keep(b))
