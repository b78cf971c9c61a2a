"""The IEEE 39-bus and 300-bus networks of the PARS load-shedding study.

Both start from the MATPOWER case files (`case39`: the New England system,
Athay et al. 1979 / Pai 1989; `case300`: the IEEE 300-bus test case), as
shipped by PYPOWER.

`ieee39` then applies the study's change to the network (PNNL file
IEEE39bus_multiloads_xfmr4_smallX): the loads of buses 4, 7, 8 and 18 move
behind step-down transformers (X = 0.003 p.u. on 100 MVA, ratio 1) onto new
buses 504, 507, 508 and 518, each split into three load records of 40/40/20 %
(IDs 1-3), so that a motor model can take one record. The load values are
MATPOWER's, not the PNNL file's (which differ, e.g. 114.6 vs 84 Mvar at bus 7).

`ieee300` is the MATPOWER network unchanged for now; the study's zone-1 edits
(loads moved onto 200xx buses, HVDC link removed) come with the FIDVR case.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from jaxgrid.case import PQ, Case, build_case, to_rows
from jaxgrid.cases.registry import register
from jaxgrid.io.matpower import load_pypower_case

STUDY_LOAD_BUSES_39 = (4, 7, 8, 18)
STEP_DOWN_X = 0.003  # p.u. on the system base, as in the PNNL "smallX" file
LOAD_SPLIT = (0.4, 0.4, 0.2)


def move_loads_behind_transformers(case: Case, buses, offset: int,
                                   x: float | Mapping[int, float], split=LOAD_SPLIT) -> Case:
    """Move each bus's loads onto a new bus `offset + bus` behind a transformer of reactance x.

    `x` is p.u. on the system base: one value for every transformer, or a mapping from the
    original bus number to its transformer's reactance. The moved load is split into
    len(split) records with IDs "1", "2", ... (fractions of the bus total). Returns a new
    validated case.
    """
    rows = to_rows(case)
    by_number = {row["number"]: row for row in rows["buses"]}
    kept_loads = []
    for bus in buses:
        new = offset + bus
        if new in by_number:
            raise ValueError(f"{case.name}: bus {new} exists already; choose another offset")
        rows["buses"].append(dict(by_number[bus], number=new, name=f"LOAD {bus}", kind=PQ))
        at_bus = [ld for ld in rows["loads"] if ld["bus"] == bus]
        if not at_bus:
            raise ValueError(f"{case.name}: bus {bus} has no load to move")
        total = {k: sum(ld[k] for ld in at_bus) for k in (
            "p_power", "q_power", "p_current", "q_current", "p_impedance", "q_impedance")}
        for k, share in enumerate(split, start=1):
            kept_loads.append(dict(at_bus[0], bus=new, load_id=str(k),
                                   **{key: value * share for key, value in total.items()}))
        rows["branches"].append(dict(
            from_bus=bus, to_bus=new, ckt="1", in_service=True, r=0.0,
            x=x[bus] if isinstance(x, Mapping) else x, b=0.0, tap=1.0,
            shift=0.0, g_from=0.0, b_from=0.0, g_to=0.0, b_to=0.0, is_transformer=True,
            line=0))
    rows["loads"] = [ld for ld in rows["loads"] if ld["bus"] not in buses] + kept_loads
    return build_case(**rows)


@register("ieee39")
def ieee39() -> Case:
    """IEEE 39-bus (New England), the study's loads at 504/507/508/518 behind transformers."""
    case = move_loads_behind_transformers(load_pypower_case("case39"), STUDY_LOAD_BUSES_39,
                                          offset=500, x=STEP_DOWN_X)
    return _renamed(case, "ieee39")


@register("ieee300")
def ieee300() -> Case:
    """IEEE 300-bus test system (MATPOWER data)."""
    return _renamed(load_pypower_case("case300"), "ieee300")


def _renamed(case: Case, name: str) -> Case:
    return dataclasses.replace(case, name=name)
