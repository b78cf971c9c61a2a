"""MATPOWER case data (version 2 `ppc` dicts, as shipped by PYPOWER) to a `Case`.

Columns follow the MATPOWER manual, appendix B (bus, gen, branch data): bus
PD/QD become one constant-power load per bus, GS/BS a bus shunt, TAP = 0 means
a line (ratio 1), SHIFT is in degrees. Error messages name the matrix row as
`source:row` (1-based).
"""
from __future__ import annotations

import importlib
import math

import numpy as np

from jaxgrid.case import Case, build_case

# MATPOWER column indices (0-based), manual appendix B.
BUS_I, BUS_TYPE, PD, QD, GS, BS, BUS_AREA, VM, VA, BASE_KV, ZONE = range(11)
GEN_BUS, PG, QG, QMAX, QMIN, VG, MBASE, GEN_STATUS, PMAX, PMIN = range(10)
F_BUS, T_BUS, BR_R, BR_X, BR_B, RATE_A, RATE_B, RATE_C, TAP, SHIFT, BR_STATUS = range(11)


def from_matpower(ppc: dict, name: str, source: str | None = None) -> Case:
    """Build a validated `Case` from a MATPOWER case dict (baseMVA, bus, gen, branch)."""
    source = source or name
    base = float(ppc["baseMVA"])
    bus, gen, branch = (np.asarray(ppc[k], dtype=float) for k in ("bus", "gen", "branch"))
    buses, loads, shunts = [], [], []
    for row, b in enumerate(bus, start=1):
        number = int(b[BUS_I])
        buses.append(dict(number=number, name=str(number), kind=int(b[BUS_TYPE]),
                          base_kv=b[BASE_KV], area=int(b[BUS_AREA]), zone=int(b[ZONE]),
                          vm=b[VM], va=math.radians(b[VA]), line=row))
        if b[PD] or b[QD]:
            loads.append(dict(bus=number, load_id="1", in_service=True, p_power=b[PD] / base,
                              q_power=b[QD] / base, p_current=0.0, q_current=0.0,
                              p_impedance=0.0, q_impedance=0.0, line=row))
        if b[GS] or b[BS]:
            shunts.append(dict(bus=number, shunt_id="bus", in_service=True, g=b[GS] / base,
                               b=b[BS] / base, line=row))
    units: dict[int, int] = {}
    generators = []
    for row, g in enumerate(gen, start=1):
        number = int(g[GEN_BUS])
        units[number] = units.get(number, 0) + 1
        generators.append(dict(
            bus=number, gen_id=str(units[number]), in_service=g[GEN_STATUS] > 0,
            pg=g[PG] / base, qg=g[QG] / base, qmax=g[QMAX] / base, qmin=g[QMIN] / base,
            pmax=g[PMAX] / base, pmin=g[PMIN] / base, vset=g[VG], reg_bus=number,
            mbase=g[MBASE] if g[MBASE] > 0 else base, zr=0.0, zx=1.0, line=row))
    circuits: dict[tuple[int, int], int] = {}
    branches = []
    for row, br in enumerate(branch, start=1):
        ends = (int(br[F_BUS]), int(br[T_BUS]))
        circuits[ends] = circuits.get(ends, 0) + 1
        branches.append(dict(
            from_bus=ends[0], to_bus=ends[1], ckt=str(circuits[ends]), in_service=br[BR_STATUS] > 0,
            r=br[BR_R], x=br[BR_X], b=br[BR_B], tap=br[TAP] if br[TAP] else 1.0,
            shift=math.radians(br[SHIFT]), g_from=0.0, b_from=0.0, g_to=0.0, b_to=0.0,
            is_transformer=bool(br[TAP]) or bool(br[SHIFT]), line=row))
    zones = {int(z): str(int(z)) for z in np.unique(bus[:, ZONE])}
    areas = {int(a): str(int(a)) for a in np.unique(bus[:, BUS_AREA])}
    return build_case(name=name, source=source, base_mva=base, frequency_hz=60.0, buses=buses,
                      loads=loads, shunts=shunts, generators=generators, branches=branches,
                      areas=areas, zones=zones)


def load_pypower_case(name: str) -> Case:
    """A case shipped with PYPOWER, e.g. "case39", "case300", as a `Case`."""
    try:
        module = importlib.import_module(f"pypower.{name}")
    except ModuleNotFoundError:
        raise ValueError(f"pypower has no case named {name!r} (e.g. 'case39', 'case300')") from None
    return from_matpower(getattr(module, name)(), name=name, source=f"pypower.{name}")
