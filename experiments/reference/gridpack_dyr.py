"""The DYR side of the GridPACK reference: model-level variants of a DYR's motor loads
(`MotorEdit`, `edited_dyr`: some A/C motors kept, CONs changed, records added, a composite
load placed), the DYR as GridPACK reads it (`gridpack_dyr`: no byte-order mark, CMLDBLU2 as
CMLDBLU1) and where GridPACK puts a composite load's internal buses (`composite_buses`).
The command is `experiments.reference.gridpack`.

CMLDBLU2 and CMLDBLU1 share their first 132 CONs (`jaxgrid.models.cmld_cons`, GridPACK's
`cmldblu1.hpp` reads the same order); CMLDBLU2 adds two ICONs before them and Frcel after
them. GridPACK reads only CMLDBLU1, so a CMLDBLU2 record is written for it as the CMLDBLU1
record of its first 132 CONs: the same load where Frcel (the share of dropped electronic load
that comes back) plays no part, i.e. where Fel = 0 (GridPACK has no electronic load) or
Frcel = 0 (what jaxgrid reads for a CMLDBLU1).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import NamedTuple

import numpy as np

from jaxgrid.case import Case
from jaxgrid.io.dyr import read_dyr
from jaxgrid.models.acmotor import Acmtblu1
from jaxgrid.models.cmld import Cmldblu1, composite_records
from jaxgrid.models.cmld_init import internal_buses
from jaxgrid.models.exciters import EXCITERS
from jaxgrid.records import DyrRecord

COMPOSITE = ("CMLDBLU2", "CMLDBLU1")
CMLD_NAMES = [c.name for c in Cmldblu1.cons]  # the 132 CONs both records share


@dataclasses.dataclass(frozen=True)
class MotorEdit:
    """ACMTBLU1 records to keep (RAW bus numbers; empty: all), CONs to set on them
    ({name: value}, names as in `jaxgrid.models.acmotor.Acmtblu1.cons`), DYR records to
    add (text, e.g. a CIM6BL), each replacing the ACMTBLU1 of its bus and load id; a dropped
    motor's load stays a static load. Composite loads: `cmld_source` ("FILE:BUS", a
    CMLDBLU1/2 record of another DYR) is placed, as a CMLDBLU1 record, at each `cmld_at`
    ("BUS:ID", replacing an ACMTBLU1 there), and `cmld_cons` (names as in
    `jaxgrid.models.cmld_cons`) are set on every composite record. `exciter_source`
    ("FILE:BUS"): every exciter is replaced by that file's exciter record at BUS (e.g.
    GridPACK's 300-bus case with the 39-bus EXDC1: GridPACK's ESST1A aborts on it)."""

    keep: tuple[int, ...] = ()
    cons: tuple[tuple[str, float], ...] = ()
    records: tuple[str, ...] = ()
    cmld_source: str = ""
    cmld_at: tuple[str, ...] = ()
    cmld_cons: tuple[tuple[str, float], ...] = ()
    exciter_source: str = ""

    @property
    def empty(self) -> bool:
        return not any(dataclasses.astuple(self))

    @classmethod
    def from_json(cls, d: dict) -> MotorEdit:
        return cls(**{f.name: _tuples(d[f.name]) for f in dataclasses.fields(cls)
                      if f.name in d})


def _tuples(value):
    """JSON lists back to (nested) tuples; strings and numbers unchanged."""
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


def _record_end(lines: list[str], record: DyrRecord) -> int:
    """Index of the line that ends `record` (the one with its '/')."""
    return next(k for k in range(record.line - 1, len(lines)) if "/" in lines[k])


def _set_cons(cons, names, changes, flag: str) -> list[float]:
    unknown = [n for n, _ in changes if n not in names]
    if unknown:
        raise ValueError(f"{flag} {unknown}: the CONs are {', '.join(names)}")
    cons = list(cons)
    for name, value in changes:
        cons[names.index(name)] = value
    return cons


def cmld_text(record: DyrRecord, bus: int, device_id: str, changes=(),
              model: str | None = None) -> str:
    """`record` (CMLDBLU1/2) at `bus`, `device_id` with CON `changes`, as a record of
    `model` (default its own): CMLDBLU1 keeps the first 132 CONs (module docstring)."""
    model = model or record.model
    cons = _set_cons(record.cons, CMLD_NAMES + ["frcel"], changes, "--cmld-cons")
    it = record.header[1] if len(record.header) > 1 else 1
    if model == "CMLDBLU1":
        head, values = f"12, {it:g}, 0, 132, 27, 146, 48", cons[:132]
    else:
        icons = ", ".join(f"{v:g}" for v in (record.icons or (0, 0)))
        head, values = f"12, {it:g}, 2, 133, 27, 146, 48, {icons}", (cons + [0.0])[:133]
    body = ", ".join(f"{v:.10g}" for v in values)
    return f"{bus}, 'USRLOD', '{device_id}', '{model}', {head}, {body} /"


def _source_record(source: str, models, flag: str) -> DyrRecord:
    """The first record of one of `models` at the bus of `source` ("FILE:BUS")."""
    path, _, bus = source.rpartition(":")
    try:
        records = [r for r in read_dyr(path, strict=False).records
                   if r.model in models and r.bus == int(bus)]
    except ValueError:
        raise ValueError(f"{flag} {source!r}: expected FILE:BUS") from None
    if not records:
        raise ValueError(f"{flag} {source!r}: no {'/'.join(models)} record at bus {bus}")
    return records[0]


def _placed(edit: MotorEdit) -> list[str]:
    """The composite records `edit` places (`cmld_source` at each `cmld_at`), as text."""
    if not edit.cmld_at:
        return []
    source = _source_record(edit.cmld_source, COMPOSITE, "--cmld-source")
    out = []
    for at in edit.cmld_at:
        bus, _, device_id = at.partition(":")
        out.append(cmld_text(source, int(bus), device_id.strip() or "1", edit.cmld_cons,
                             "CMLDBLU1"))
    return out


def edited_dyr(dyr: str, edit: MotorEdit, out: Path) -> str:
    """`dyr` with `edit` applied, written to `out` (returned); `dyr` itself when empty."""
    if edit.empty:
        return dyr
    names = [c.name for c in Acmtblu1.cons]
    lines = Path(dyr).read_text(encoding="utf-8-sig").splitlines()
    data = read_dyr(dyr)
    records = data.by_model("ACMTBLU1")
    missing = sorted(set(edit.keep) - {r.bus for r in records})
    if missing:
        raise ValueError(f"--motors {missing}: {dyr} has no ACMTBLU1 record there")
    added = [text.strip().rstrip("/").strip() + " /" for text in edit.records] + _placed(edit)
    replaced = {(r.bus, r.device_id) for r in _added_records(added, out)}
    drop, kept = set(), []
    for r in records:
        drop.update(range(r.line - 1, _record_end(lines, r) + 1))
        if (not edit.keep or r.bus in edit.keep) and (r.bus, r.device_id) not in replaced:
            cons = _set_cons(r.cons, names, edit.cons, "--motor-cons")
            values = ", ".join(f"{v:g}" for v in (*r.header, *r.icons, *cons))
            kept.append(f"{r.bus}, 'USRLOD', {r.device_id}, 'ACMTBLU1', {values} /")
    if edit.exciter_source:
        exciter = _source_record(edit.exciter_source, tuple(EXCITERS), "--exciter-source")
        values = ", ".join(f"{v:.10g}" for v in exciter.cons)
        for r in (r for r in data.records if r.model in EXCITERS):
            drop.update(range(r.line - 1, _record_end(lines, r) + 1))
            kept.append(f"{r.bus}, '{exciter.model}', '{r.device_id}', {values} /")
    if edit.cmld_cons:  # the file's own composite loads, rewritten with the changes
        for r in (r for r in data.records if r.model in COMPOSITE):
            drop.update(range(r.line - 1, _record_end(lines, r) + 1))
            kept.append(cmld_text(r, r.bus, r.device_id, edit.cmld_cons))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join([x for k, x in enumerate(lines) if k not in drop] + kept + added)
                   + "\n")
    return str(out)


def _added_records(texts: list[str], out: Path) -> list[DyrRecord]:
    """DYR records of `texts`, read through a scratch file beside `out`."""
    if not texts:
        return []
    scratch = out.with_name(out.stem + "_added.dyr")
    scratch.parent.mkdir(parents=True, exist_ok=True)
    scratch.write_text("".join(t.strip().rstrip("/").strip() + " /\n" for t in texts))
    return list(read_dyr(scratch, strict=False).records)


def motor_buses(edited: str, edit: MotorEdit) -> list[int]:
    """RAW buses of the A/C motors in `edited` (a DYR written by `edited_dyr` with `edit`)
    and of the records `edit` adds."""
    added = _added_records(list(edit.records), Path(edited))
    return sorted({r.bus for r in read_dyr(edited).by_model("ACMTBLU1")}
                  | {r.bus for r in added})


def gridpack_dyr(dyr: str, out: Path) -> list[str]:
    """Write `dyr` as GridPACK reads it to `out`: without a UTF-8 byte-order mark (its
    parser loses the first record after one; the PNNL 39-bus DYR has one) and with every
    CMLDBLU2 record as CMLDBLU1 (module docstring). Returns notes on what GridPACK's
    record leaves out (non-zero ICONs, Frcel with Fel > 0)."""
    lines = Path(dyr).read_text(encoding="utf-8-sig").splitlines()
    notes, drop, new = [], set(), []
    for r in read_dyr(dyr, strict=False).by_model("CMLDBLU2"):
        drop.update(range(r.line - 1, _record_end(lines, r) + 1))
        new.append(cmld_text(r, r.bus, r.device_id, model="CMLDBLU1"))
        frcel, fel = r.cons[132], r.cons[CMLD_NAMES.index("fel")]
        if any(r.icons) or (frcel and fel):
            notes.append(f"{dyr}:{r.line}: CMLDBLU2 at bus {r.bus}: ICONs {r.icons}, Frcel "
                         f"{frcel:g} (Fel {fel:g}) are not in GridPACK's CMLDBLU1")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join([x for k, x in enumerate(lines) if k not in drop] + new) + "\n")
    return notes


class CompositeBuses(NamedTuple):
    """A composite load's buses: its system bus and load id, jaxgrid's internal bus numbers
    (`cmld_init.internal_buses`), GridPACK's, and its motor-D share FmD."""

    bus: int
    device_id: str
    low: int
    load: int
    gridpack_low: int
    gridpack_load: int
    fmd: float


def composite_buses(case: Case, dyr: str) -> list[CompositeBuses]:
    """The composite loads of `dyr` on `case`. GridPACK numbers the added buses after the
    largest RAW bus number N: low side N + 1 + 2k, load bus N + 2 + 2k for its k-th
    composite load, counted in RAW bus order and, at a bus, in load-record order
    (`base_pti_parser.hpp`, `expandBusModels`)."""
    records = composite_records(read_dyr(dyr, strict=False).records)
    if not records:
        return []
    ours = internal_buses(case, records)
    loads = case.loads
    numbers = case.buses.number
    position = {(int(numbers[b]), str(i).strip()): k
                for k, (b, i) in enumerate(zip(loads.bus, loads.load_id))}
    order = sorted(range(len(records)), key=lambda k: (
        int(np.flatnonzero(numbers == records[k].bus)[0]),
        position.get((records[k].bus, records[k].device_id.strip()), 0)))
    top = int(numbers.max())
    rank = {k: j for j, k in enumerate(order)}
    return [CompositeBuses(r.bus, r.device_id.strip(), low, load, top + 1 + 2 * rank[k],
                           top + 2 + 2 * rank[k], r.cons[CMLD_NAMES.index("fmd")])
            for k, (r, ((low, _), (load, _))) in enumerate(zip(records, ours))]
