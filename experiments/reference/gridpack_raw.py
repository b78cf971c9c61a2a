"""A case as a PSS/E v33 RAW file, for GridPACK, which reads RAW versions 23 and 33 but not the
v30 of the PNNL 300-bus study (`IEEE300Bus_modified_noHVDC_v2.raw`): `raw33(case)` writes
what jaxgrid read (`jaxgrid.case.Case`, system p.u.) back in PSS/E's record layouts
(PSS/E 33 program operation manual, "Power Flow Raw Data File Contents"), so both simulators
start from the same network. Transformers are written with CW = CZ = CM = 1 (ratio p.u.,
impedance and magnetising admittance p.u. on the system base): the ratio and phase shift on
winding 1 (the case's from bus), winding 2 at 1 p.u.; shunts as fixed shunts (a switched
shunt at the value jaxgrid read); areas, zones and owners by number only. Reading the text
back with `jaxgrid.io.raw` gives the same case (tests/test_gridpack_cmld.py).
"""
from __future__ import annotations

import math

import numpy as np

from jaxgrid.case import Case

END = ("BUS", "LOAD", "FIXED SHUNT", "GENERATOR", "BRANCH", "TRANSFORMER", "AREA",
       "TWO-TERMINAL DC", "VOLTAGE SOURCE DC", "IMPEDANCE CORRECTION", "MULTI-TERMINAL DC",
       "MULTI-SECTION LINE", "ZONE", "INTER-AREA TRANSFER", "OWNER", "FACTS DEVICE",
       "SWITCHED SHUNT", "GNE", "INDUCTION MACHINE")


def raw33(case: Case, title: str = "written by experiments.reference.gridpack_raw") -> str:
    """The PSS/E v33 RAW text of `case` (module docstring)."""
    base = case.base_mva
    buses, number = case.buses, case.buses.number
    sections: list[list[str]] = [[] for _ in END]
    for k in range(len(number)):
        sections[0].append(
            f"{number[k]},'{buses.name[k][:12]}',{buses.base_kv[k]:.4f},{buses.kind[k]},"
            f"{buses.area[k]},{buses.zone[k]},1,{buses.vm[k]:.8f},"
            f"{math.degrees(buses.va[k]):.8f},1.1,0.9,1.1,0.9")
    ld = case.loads
    for k in range(len(ld.bus)):
        b = ld.bus[k]
        sections[1].append(
            f"{number[b]},'{ld.load_id[k]}',{int(ld.in_service[k])},{buses.area[b]},"
            f"{buses.zone[b]},{_mw(ld.p_power[k], base)},{_mw(ld.q_power[k], base)},"
            f"{_mw(ld.p_current[k], base)},{_mw(ld.q_current[k], base)},"
            f"{_mw(ld.p_impedance[k], base)},{_mw(-ld.q_impedance[k], base)},1,1,0")
    sh = case.shunts
    for k in range(len(sh.bus)):
        sections[2].append(f"{number[sh.bus[k]]},'{sh.shunt_id[k][:2]}',{int(sh.in_service[k])},"
                           f"{_mw(sh.g[k], base)},{_mw(sh.b[k], base)}")
    g = case.generators
    for k in range(len(g.bus)):
        sections[3].append(
            f"{number[g.bus[k]]},'{g.gen_id[k]}',{_mw(g.pg[k], base)},{_mw(g.qg[k], base)},"
            f"{_mw(g.qmax[k], base)},{_mw(g.qmin[k], base)},{g.vset[k]:.8f},"
            f"{number[g.reg_bus[k]] if g.reg_bus[k] != g.bus[k] else 0},{g.mbase[k]:.4f},"
            f"{g.zr[k]:.8g},{g.zx[k]:.8g},0,0,1,{int(g.in_service[k])},100,"
            f"{_mw(g.pmax[k], base)},{_mw(g.pmin[k], base)},1,1")
    br = case.branches
    for k in range(len(br.from_bus)):
        i, j = number[br.from_bus[k]], number[br.to_bus[k]]
        on, ckt = int(br.in_service[k]), br.ckt[k]
        if br.is_transformer[k]:
            sections[5] += [
                f"{i},{j},0,'{ckt}',1,1,1,{br.g_from[k]:.10g},{br.b_from[k]:.10g},2,"
                f"'            ',{on},1,1",
                f"{br.r[k]:.10g},{br.x[k]:.10g},{base:g}",
                f"{br.tap[k]:.10g},0,{math.degrees(br.shift[k]):.10g},0,0,0,0,0,1.1,0.9,1.1,"
                "0.9,33,0,0,0,0",
                "1,0"]
        else:
            sections[4].append(
                f"{i},{j},'{ckt}',{br.r[k]:.10g},{br.x[k]:.10g},{br.b[k]:.10g},0,0,0,"
                f"{br.g_from[k]:.10g},{br.b_from[k]:.10g},{br.g_to[k]:.10g},"
                f"{br.b_to[k]:.10g},{on},1,0,1,1")
    sections[6] = [f"{a},0,0,10,'{name[:12]}'" for a, name in sorted(case.areas.items())]
    sections[12] = [f"{z},'{name[:12]}'" for z, name in sorted(case.zones.items())]
    lines = [f"0,{base:g},33,0,1,60.00", title, ""]
    for k, (rows, name) in enumerate(zip(sections, END)):
        following = f", BEGIN {END[k + 1]} DATA" if k + 1 < len(END) else ""
        lines += rows + [f"0 / END OF {name} DATA{following}"]
    lines.append("Q")
    return "\n".join(lines) + "\n"


def _mw(value, base: float) -> str:
    """A p.u. quantity in MW/Mvar on `base` MVA."""
    return f"{float(np.asarray(value)) * base:.8f}"
