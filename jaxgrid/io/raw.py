"""PSS/E RAW power-flow data reader: versions 23, 30, 31-33, 34 and 35.

Follows the record layouts of the PSS/E Program Operation Manual (POM),
"Power Flow Raw Data File Contents", for each revision:

- v23 (no REV field in the first line): loads and bus shunts live in the bus
  record (I, IDE, PL, QL, GL, BL, IA, VM, VA, NAME, BASKV, ZONE); transformers
  are branch records with a non-zero RATIO; tap-adjustment records follow.
- v30: bus (I, NAME, BASKV, IDE, GL, BL, AREA, ZONE, VM, VA, OWNER), separate
  load data, two- and three-winding transformer records of 4/5 lines.
- v31-v33: bus without GL/BL, a fixed-shunt section, switched shunts after FACTS.
- v34: a system-wide data section (solution parameters, rating-set names) before
  the buses; branches with a NAME and 12 ratings (GI, BI, GJ, BJ, ST at fields
  20-24); a system switching device section after the branches (read as branches
  of reactance X, STAT); 12 ratings per transformer winding (COD at field 16);
  loads with distributed generation (DGENP, DGENQ, DGENM); impedance-correction
  tables over several lines (a table ends on a line with fewer than six
  non-zero points); a substation section at the end (each substation followed by
  its node, switching-device and terminal blocks, each closed by `0`); `@!`
  lines are column headings. Generators and switched shunts as in v33, NREG last.
- v35: v34 with NREG after IREG in generator records (MBASE at field 10, STAT at
  16, PT/PB at 18/19) and an ID after I in switched shunts (STAT at field 5, BINIT
  at 12), as GridPACK's PTI35 parser and powsybl's v35 records read them.

Reading real files as they are written (each assumption is a note in `Case.notes`):
- a first line without REV is v23 unless the first bus record says otherwise: a
  quoted (or non-numeric) NAME as its second field is v30 (11 fields) or v33
  (otherwise); the version inferred is noted. v34/v35 cannot be told from their
  records; a file without REV that has a system-wide data section needs
  `version=`;
- a file may end after its last non-empty section, with or without that
  section's closing `0` line: the sections not given are empty (noted). A file
  that ends before the transformer data, or inside a multi-line record, is
  truncated (CaseError).
- a v34/v35 file whose bus records follow the title lines has no system-wide
  data section (noted).

Modelled: buses, loads (constant power/current/admittance parts), fixed and bus
shunts, switched shunts (fixed at BINIT), generators, branches with line
shunts, two-winding transformers (all CW/CZ/CM codes, taps, phase shift,
magnetising admittance) and three-winding transformers (star equivalent; the
star bus gets a negative number -1, -2, ...), areas and zones. Everything else
(DC lines, FACTS, GNE, induction machines, impedance-correction tables,
tap-adjustment data, multi-section line groupings, owners, inter-area
transfers) is counted in `Case.skipped` and named in one `RawWarning`.
Impedances given on a winding MVA base are converted to the system base; the
winding *voltage* base is taken as the bus base (as MATPOWER's psse2mpc does).
"""
from __future__ import annotations

import cmath
import math
import warnings
from pathlib import Path
from typing import Any

from jaxgrid.case import ISOLATED, TAP_RATIO, VOLTAGE, Case, CaseError, build_case
from jaxgrid.checks import Range

SUPPORTED_VERSIONS = (23, 30, 31, 32, 33, 34, 35)

_SECTIONS = {
    23: ("bus", "generator", "branch", "transformer adjustment", "area", "two-terminal dc",
         "switched shunt", "impedance correction", "multi-terminal dc", "multi-section line",
         "zone", "inter-area transfer", "owner", "facts"),
    30: ("bus", "load", "generator", "branch", "transformer", "area", "two-terminal dc",
         "vsc dc", "switched shunt", "impedance correction", "multi-terminal dc",
         "multi-section line", "zone", "inter-area transfer", "owner", "facts"),
    33: ("bus", "load", "fixed shunt", "generator", "branch", "transformer", "area",
         "two-terminal dc", "vsc dc", "impedance correction", "multi-terminal dc",
         "multi-section line", "zone", "inter-area transfer", "owner", "facts",
         "switched shunt", "gne", "induction machine"),
    34: ("system-wide", "bus", "load", "fixed shunt", "generator", "branch", "switching device",
         "transformer", "area", "two-terminal dc", "vsc dc", "impedance correction",
         "multi-terminal dc", "multi-section line", "zone", "inter-area transfer", "owner",
         "facts", "switched shunt", "gne", "induction machine", "substation"),
}
_SECTIONS[35] = _SECTIONS[34]
_LAYOUT = {23: 23, 30: 30, 31: 33, 32: 33, 33: 33, 34: 34, 35: 35}
# A file may end after these sections; stopping earlier means it is truncated.
_REQUIRED = {23: "branch", 30: "transformer", 33: "transformer", 34: "transformer",
             35: "transformer"}
_LINES_PER_RECORD = {"two-terminal dc": 3, "vsc dc": 3}
# Field indices (0-based) that moved between layouts.
_GENERATOR = {35: dict(mbase=9, zr=10, zx=11, stat=15, pt=17, pb=18)}
_GENERATOR_V33 = dict(mbase=8, zr=9, zx=10, stat=14, pt=16, pb=17)
_BRANCH_SHUNTS = {23: (11, 12, 13, 14, 15), 34: (19, 20, 21, 22, 23), 35: (19, 20, 21, 22, 23)}
_BRANCH_SHUNTS_V30 = (9, 10, 11, 12, 13)  # GI, BI, GJ, BJ, ST of v30-v33
_SWITCHED_SHUNT = {23: (5, None), 30: (7, None), 33: (9, 3), 34: (9, 3), 35: (11, 4)}  # BINIT, STAT
_END_OF_DATA = "Q"  # PSS/E's end-of-data line
_END_OF_FILE = "end of file"
THRSHZ = 1e-4  # p.u.: PSS/E's zero-impedance threshold

# Any RAW real beyond this magnitude is a typing error (MW, Mvar, kV, p.u., W all stay far
# below it); integers are Fortran INTEGER*4; bus numbers as PSS/E allows.
REAL_FIELD = Range(-1e12, 1e12)
INT_FIELD = Range(-(2 ** 31 - 1), 2 ** 31 - 1)
BUS_NUMBER = Range(1, 999_999)
DC_COUNT = Range(0, 10_000)  # converters, dc buses or dc links of a multi-terminal dc line
SYSTEM_BASE = Range(0, 1e6, "MVA", lo_open=True)
BASE_KV = Range(0, 1e4, "kV")
FREQUENCY = Range(0, 1e3, "Hz")


class RawWarning(UserWarning):
    """Records the reader does not model (named and counted)."""


def split_fields(text: str) -> list[str]:
    """Split one data line into fields (commas and/or blanks; quotes kept whole).

    Everything after a `/` outside quotes is a comment. Two commas in a row give
    an empty field, which means "use the default".
    """
    fields: list[str] = []
    i, n = 0, len(text)
    while True:
        while i < n and text[i] in " \t\r\n":
            i += 1
        if i >= n or text[i] == "/":
            return fields
        if text[i] in "'\"":
            end = text.find(text[i], i + 1)
            end = n if end < 0 else end
            fields.append(text[i + 1:end].strip())
            i = end + 1
        elif text[i] == ",":
            fields.append("")
            i += 1
            continue
        else:
            j = i
            while j < n and text[j] not in ", \t\r\n/":
                j += 1
            fields.append(text[i:j])
            i = j
        while i < n and text[i] in " \t\r\n":
            i += 1
        if i < n and text[i] == ",":
            i += 1


class _Record:
    """Fields of one record with typed, error-reporting accessors."""

    def __init__(self, fields: list[str], source: str, line: int, what: str):
        self.fields, self.source, self.line, self.what = fields, source, line, what

    def _raw(self, i: int) -> str:
        return self.fields[i] if i < len(self.fields) else ""

    def num(self, i: int, name: str, default: float | None = None,
            allowed: Range = REAL_FIELD) -> float:
        """Field i as a float, CaseError naming it when missing, not a number or outside
        `allowed`."""
        text = self._raw(i)
        if text == "":
            if default is None:
                raise CaseError(f"{self.what}: {name} is missing (field {i + 1})",
                                self.source, self.line)
            return default
        try:
            value = float(text.replace("D", "E").replace("d", "e"))
        except ValueError:
            raise CaseError(f"{self.what}: {name} = '{text}' is not a number",
                            self.source, self.line) from None
        if not math.isfinite(value):
            raise CaseError(f"{self.what}: {name} = {text} is not finite", self.source, self.line)
        reason = allowed.problem(value)
        if reason:
            raise CaseError(f"{self.what}: {name} = {text}: {reason}", self.source, self.line)
        return value

    def int(self, i: int, name: str, default: int | None = None,
            allowed: Range = INT_FIELD) -> int:
        value = self.num(i, name, None if default is None else float(default), allowed)
        if value != int(value):
            raise CaseError(f"{self.what}: {name} = {self._raw(i)} is not an integer",
                            self.source, self.line)
        return int(value)

    def text(self, i: int, default: str = "1") -> str:
        return self._raw(i).strip() or default


class _Lines:
    """Cursor over the file's lines (1-based numbers)."""

    def __init__(self, text: str, source: str):
        self.lines = text.splitlines()
        self.pos = 0
        self.source = source

    def next(self, what: str) -> tuple[int, str]:
        if self.pos >= len(self.lines):
            raise CaseError(f"unexpected end of file in {what}", self.source, len(self.lines))
        self.pos += 1
        return self.pos, self.lines[self.pos - 1]

    def at_end(self) -> bool:
        return self.pos >= len(self.lines)


def _stated_version(first: list[str], source: str) -> int | None:
    """REV of the case identification record, None when the field is absent."""
    if len(first) < 3 or first[2] == "":
        return None
    try:
        version = int(float(first[2]))
    except (ValueError, OverflowError):
        raise CaseError(f"case identification: REV = '{first[2]}' is not a number", source, 1)
    if version not in SUPPORTED_VERSIONS:
        raise CaseError(f"case identification: REV = {version}: RAW version not supported "
                        f"(supported: {', '.join(map(str, SUPPORTED_VERSIONS))})", source, 1)
    return version


def _quoted_field(text: str) -> int | None:
    """Index of the first quoted field of a data line, None when it has none."""
    quotes = [i for i in (text.find("'"), text.find('"')) if i >= 0]
    if not quotes:
        return None
    before = text[:min(quotes)]
    return None if "/" in before else len(split_fields(before))


def _is_number(text: str) -> bool:
    try:
        float(text.replace("D", "E").replace("d", "e"))
    except ValueError:
        return False
    return True


def infer_version(text: str) -> int | None:
    """The RAW version the first data record after the title lines implies, for a file without
    REV: 30 when its second field is a NAME (quoted, or not a number) in an 11-field record
    (v30 has GL, BL), 33 for a NAME otherwise (v31-v33: 9 fields, v33: 13), else 23 (the
    second field is the type IDE; NAME is 10th). None when the line is no bus record (a
    v34/v35 system-wide data record, a `0` line)."""
    fields = split_fields(text)
    if len(fields) < 2 or not _is_number(fields[0]) or fields[0].strip() == "0":
        return None
    quoted = _quoted_field(text)
    if quoted == 1 or (quoted is None and not _is_number(fields[1])):  # a NAME second
        return 30 if len(fields) == 11 else 33
    return 23


class _RawParser:
    """Reads one RAW file into rows for `build_case`."""

    def __init__(self, text: str, source: str, version: int | None):
        self.source = source
        self.cursor = _Lines(text.lstrip("\ufeff"), source)
        self.notes: list[str] = []
        _, first = self.cursor.next("case identification")
        head = _Record(split_fields(first), source, 1, "case identification")
        stated = _stated_version(head.fields, source)
        self.cursor.next("case title")
        self.cursor.next("case title")
        self.version = version or stated or self._inferred_version()
        self.layout = _LAYOUT[self.version]
        self.base_mva = head.num(1, "SBASE", 100.0, SYSTEM_BASE)
        self.frequency = 60.0 if self.version == 23 else head.num(
            5, "BASFRQ", 60.0, FREQUENCY) or 60.0
        self.rows: dict[str, list[dict[str, Any]]] = {
            k: [] for k in ("buses", "loads", "shunts", "generators", "branches")}
        self.areas: dict[int, str] = {}
        self.zones: dict[int, str] = {}
        self.skipped: dict[str, int] = {}
        self.bus_rows: dict[int, dict[str, Any]] = {}
        self.star_count = 0
        self.transformer_lines: dict[tuple, int] = {}  # (buses, ckt) -> first line

    def _next_data_line(self) -> int | None:
        """0-based index of the next line that is neither blank nor an `@!` heading."""
        lines = self.cursor.lines
        return next((k for k in range(self.cursor.pos, len(lines))
                     if lines[k].strip() and not lines[k].lstrip().startswith("@!")), None)

    def _inferred_version(self) -> int:
        """The version of a file without REV, from its first data record (`infer_version`):
        23 (PSS/E's reading of a missing REV) silently, another with a note."""
        first = self._next_data_line()
        if first is None:
            return 23
        version = infer_version(self.cursor.lines[first])
        if version is None:
            raise CaseError("case identification has no REV and the first data record "
                            f"(line {first + 1}) is no v23, v30 or v33 bus record: the RAW "
                            "version cannot be inferred; give it (read_raw(path, version=34))",
                            self.source, 1)
        if version != 23:
            self.notes.append(f"{self.source}:1: case identification has no REV; read as "
                              f"v{version}, the layout of the bus record at line {first + 1}")
        return version

    # -- driving -------------------------------------------------------------
    def parse(self) -> None:
        sections = _SECTIONS[self.layout]
        required = sections.index(_REQUIRED[self.layout])
        for k, section in enumerate(sections):
            if section == "system-wide" and self._bus_data_first():
                continue
            ended, n_records = self._section(section)
            if ended is None:
                continue
            if ended == _END_OF_FILE:
                if k <= required:
                    raise CaseError(
                        f"unexpected end of file in {section} data (the section's closing "
                        "'0' line is missing)" if n_records else
                        f"unexpected end of file before {section} data",
                        self.source, len(self.cursor.lines))
                where = (f"in the {section} data, without its closing '0' line" if n_records
                         else f"before the {section} data")
                self.notes.append(
                    f"{self.source}:{len(self.cursor.lines)}: the file ends {where}; the "
                    f"sections from there on ({', '.join(sections[k:])}) hold no more records")
            return

    def _bus_data_first(self) -> bool:
        """Whether a v34+ file goes from its title lines straight to bus records (no
        system-wide data section, as some writers leave it out), noted."""
        first = self._next_data_line()
        if first is None or infer_version(self.cursor.lines[first]) is None:
            return False
        self.notes.append(f"{self.source}:{first + 1}: no system-wide data section: the bus "
                          "data begin here")
        return True

    def _record_start(self, section: str) -> tuple[int, list[str]] | str | None:
        """Next record's first line, None at the section's closing `0` line, `_END_OF_DATA`
        at a `Q` line, `_END_OF_FILE` when the file ends first. Blank lines and `@!` column
        headings are passed over."""
        while not self.cursor.at_end():
            number, text = self.cursor.next(f"{section} data")
            stripped = text.strip()
            if stripped.startswith("@!"):
                continue
            if stripped.upper().startswith("Q"):
                return _END_OF_DATA
            fields = split_fields(text)
            if not fields:
                continue
            if fields[0].strip() == "0":
                return None
            return number, fields
        return _END_OF_FILE

    def _section(self, section: str) -> tuple[str | None, int]:
        """Read one section: (None after its closing `0` line, else how the data ended:
        `_END_OF_DATA` or `_END_OF_FILE`; the number of records read)."""
        handler = getattr(self, "_" + section.replace(" ", "_").replace("-", "_"), None)
        n_records = 0
        while True:
            start = self._record_start(section)
            if start is None or isinstance(start, str):
                return start, n_records
            number, fields = start
            record = _Record(fields, self.source, number, f"{section} record")
            if handler is None:
                self._skip(section, record)
            else:
                handler(record)
            n_records += 1

    def _skip(self, section: str, rec: _Record) -> None:
        """Count a record of a section not modelled and pass over its continuation lines: a
        multi-terminal dc record has one per converter, dc bus and dc link (NCONV + NDCBS +
        NDCLN); a GNE record a status line and its REAL, INTG and CHAR values, ten per line;
        a v34+ impedance-correction table runs until a line with fewer than six non-zero
        points; a v34+ substation its node, switching-device and terminal blocks."""
        extra = _LINES_PER_RECORD.get(section, 1) - 1
        if section == "multi-terminal dc" and len(rec.fields) >= 4:
            extra = sum(rec.int(k, name, allowed=DC_COUNT)
                        for k, name in ((1, "NCONV"), (2, "NDCBS"), (3, "NDCLN")))
        elif section == "gne":
            n_term = rec.int(2, "NTERM", allowed=DC_COUNT)
            counts = [rec.int(3 + n_term + k, name, 0, DC_COUNT)
                      for k, name in enumerate(("NREAL", "NINTG", "NCHAR"))]
            extra = 1 + sum(-(-c // 10) for c in counts)
        elif section == "impedance correction" and self.layout >= 34:
            self._skip_table(rec)
        elif section == "substation":
            for block in ("node", "switching device", "equipment terminal"):
                while self._record_start(f"substation {block}") not in (None, _END_OF_DATA,
                                                                         _END_OF_FILE):
                    pass
        for _ in range(extra):
            self.cursor.next(f"{section} data")
        self.skipped[section] = self.skipped.get(section, 0) + 1

    def _skip_table(self, rec: _Record) -> None:
        """Pass over the lines of a v34+ impedance-correction table (record `rec`: I, then
        points T, Re(F), Im(F), six per line): it ends on the first line with fewer than six
        non-zero points (PSS/E closes a table with a 0.0, 0.0, 0.0 point)."""
        line, first = rec, 1
        while True:
            values = [line.num(k, f"field {k + 1}", 0.0) for k in range(first, len(line.fields))]
            if sum(any(values[j:j + 3]) for j in range(0, len(values), 3)) < 6:
                return
            line, first = self._continuation(rec), 0

    # -- records -------------------------------------------------------------
    def _bus(self, rec: _Record) -> None:
        if self.layout == 23:
            i, ide, area, vm, va, name, kv, zone = 0, 1, 6, 7, 8, 9, 10, 11
        elif self.layout == 30:
            i, name, kv, ide, area, zone, vm, va = 0, 1, 2, 3, 6, 7, 8, 9
        else:
            i, name, kv, ide, area, zone, vm, va = 0, 1, 2, 3, 4, 5, 7, 8
        number = rec.int(i, "I", allowed=BUS_NUMBER)
        rec.what = f"bus {number}"
        kind = rec.int(ide, "IDE", 1)
        if kind not in (1, 2, 3, 4):
            raise CaseError(f"bus {number}: IDE = {kind}: must be 1, 2, 3 or 4",
                            self.source, rec.line)
        row = dict(
            number=number, name=rec.text(name, ""), kind=kind,
            base_kv=rec.num(kv, "BASKV", 0.0, BASE_KV),
            area=rec.int(area, "AREA", 1), zone=rec.int(zone, "ZONE", 1),
            vm=rec.num(vm, "VM", 1.0), va=math.radians(rec.num(va, "VA", 0.0)), line=rec.line)
        self.bus_rows[number] = row
        self.rows["buses"].append(row)
        if self.layout == 23:
            self._add_load(number, "1", True, rec.num(2, "PL", 0.0), rec.num(3, "QL", 0.0),
                           0.0, 0.0, 0.0, 0.0, rec.line)
            self._add_shunt(number, "bus", True, rec.num(4, "GL", 0.0), rec.num(5, "BL", 0.0),
                            rec.line)
        elif self.layout == 30:
            self._add_shunt(number, "bus", True, rec.num(4, "GL", 0.0), rec.num(5, "BL", 0.0),
                            rec.line)

    def _add_load(self, bus, load_id, on, pl, ql, ip, iq, yp, yq, line) -> None:
        if self.layout == 23 and pl == 0 and ql == 0:
            return
        s = self.base_mva
        self.rows["loads"].append(dict(
            bus=bus, load_id=load_id, in_service=on, p_power=pl / s, q_power=ql / s,
            p_current=ip / s, q_current=iq / s, p_impedance=yp / s, q_impedance=-yq / s,
            line=line))

    def _add_shunt(self, bus, shunt_id, on, g_mw, b_mvar, line) -> None:
        if g_mw == 0 and b_mvar == 0 and shunt_id in ("bus", "sw"):
            return
        self.rows["shunts"].append(dict(bus=bus, shunt_id=shunt_id, in_service=on,
                                        g=g_mw / self.base_mva, b=b_mvar / self.base_mva,
                                        line=line))

    def _load(self, rec: _Record) -> None:
        bus, load_id = rec.int(0, "I"), rec.text(1)
        rec.what = f"load at bus {bus} id '{load_id}'"
        pl, ql = rec.num(5, "PL", 0.0), rec.num(6, "QL", 0.0)
        if self.layout >= 34 and rec.int(16, "DGENM", 0) != 0:
            dgen_p, dgen_q = rec.num(14, "DGENP", 0.0), rec.num(15, "DGENQ", 0.0)
            if dgen_p or dgen_q:
                self.notes.append(f"{self.source}:{rec.line}: {rec.what}: distributed "
                                  f"generation DGENP = {dgen_p:g} MW, DGENQ = {dgen_q:g} Mvar "
                                  "(DGENM on) taken off its constant-power part")
                pl, ql = pl - dgen_p, ql - dgen_q
        self._add_load(bus, load_id, rec.int(2, "STATUS", 1) != 0, pl, ql,
                       rec.num(7, "IP", 0.0), rec.num(8, "IQ", 0.0), rec.num(9, "YP", 0.0),
                       rec.num(10, "YQ", 0.0), rec.line)

    def _fixed_shunt(self, rec: _Record) -> None:
        bus, shunt_id = rec.int(0, "I"), rec.text(1)
        rec.what = f"fixed shunt at bus {bus} id '{shunt_id}'"
        self._add_shunt(bus, shunt_id, rec.int(2, "STATUS", 1) != 0, rec.num(3, "GL", 0.0),
                        rec.num(4, "BL", 0.0), rec.line)

    def _switched_shunt(self, rec: _Record) -> None:
        bus = rec.int(0, "I")
        rec.what = f"switched shunt at bus {bus}"
        binit, status = _SWITCHED_SHUNT[self.layout]
        on = True if status is None else rec.int(status, "STAT", 1) != 0
        self._add_shunt(bus, "sw", on, 0.0, rec.num(binit, "BINIT", 0.0), rec.line)

    def _generator(self, rec: _Record) -> None:
        bus, gen_id = rec.int(0, "I"), rec.text(1)
        rec.what = f"generator at bus {bus} id '{gen_id}'"
        s = self.base_mva
        at = _GENERATOR.get(self.layout, _GENERATOR_V33)
        mbase = rec.num(at["mbase"], "MBASE", s)
        if mbase <= 0:
            self.notes.append(f"{self.source}:{rec.line}: {rec.what}: MBASE = {mbase:g}, "
                              f"using the system base {s:g} MVA")
            mbase = s
        reg = rec.int(7, "IREG", 0)
        qt, qb = rec.num(4, "QT", 9999.0), rec.num(5, "QB", -9999.0)
        if qt < qb:
            raise CaseError(f"{rec.what}: QT = {qt:g} Mvar < QB = {qb:g} Mvar: the reactive "
                            "limits need QB <= QT", self.source, rec.line)
        self.rows["generators"].append(dict(
            bus=bus, gen_id=gen_id, in_service=rec.int(at["stat"], "STAT", 1) != 0,
            pg=rec.num(2, "PG", 0.0) / s, qg=rec.num(3, "QG", 0.0) / s,
            qmax=qt / s, qmin=qb / s,
            vset=rec.num(6, "VS", 1.0, VOLTAGE), reg_bus=reg if reg != 0 else bus, mbase=mbase,
            zr=rec.num(at["zr"], "ZR", 0.0), zx=rec.num(at["zx"], "ZX", 1.0),
            pmax=rec.num(at["pt"], "PT", 9999.0) / s, pmin=rec.num(at["pb"], "PB", -9999.0) / s,
            line=rec.line))

    def _branch(self, rec: _Record) -> None:
        i, j, ckt = rec.int(0, "I"), abs(rec.int(1, "J")), rec.text(2)
        rec.what = f"branch {i}-{j} ckt '{ckt}'"
        ratio, angle = 0.0, 0.0
        if self.layout == 23:
            ratio, angle = rec.num(9, "RATIO", 0.0), rec.num(10, "ANGLE", 0.0)
            if ratio != 0:
                self._check_ratio(rec, "RATIO", ratio)
        gi, bi, gj, bj, st = _BRANCH_SHUNTS.get(self.layout, _BRANCH_SHUNTS_V30)
        self.rows["branches"].append(dict(
            from_bus=i, to_bus=j, ckt=ckt, in_service=rec.int(st, "ST", 1) != 0,
            r=rec.num(3, "R", 0.0), x=rec.num(4, "X"), b=rec.num(5, "B", 0.0),
            tap=ratio if ratio != 0 else 1.0, shift=math.radians(angle),
            g_from=rec.num(gi, "GI", 0.0), b_from=rec.num(bi, "BI", 0.0),
            g_to=rec.num(gj, "GJ", 0.0), b_to=rec.num(bj, "BJ", 0.0),
            is_transformer=ratio != 0, line=rec.line))

    def _switching_device(self, rec: _Record) -> None:
        """A v34+ system switching device (I, J, CKT, X, 12 ratings, STAT, ...): a branch of
        reactance X (default and floor THRSHZ, as PSS/E treats it), in service when closed."""
        i, j, ckt = rec.int(0, "I"), abs(rec.int(1, "J")), rec.text(2)
        rec.what = f"switching device {i}-{j} ckt '{ckt}'"
        x = rec.num(3, "X", THRSHZ)
        if abs(x) < THRSHZ:
            self.notes.append(f"{self.source}:{rec.line}: {rec.what}: X = {x:g} p.u. is below "
                              f"THRSHZ; using X = {THRSHZ:g} p.u.")
            x = THRSHZ
        self.rows["branches"].append(dict(
            from_bus=i, to_bus=j, ckt=ckt, in_service=rec.int(16, "STAT", 1) != 0,
            r=0.0, x=x, b=0.0, tap=1.0, shift=0.0, g_from=0.0, b_from=0.0, g_to=0.0,
            b_to=0.0, is_transformer=False, line=rec.line))

    # -- transformers --------------------------------------------------------
    def _transformer(self, rec: _Record) -> None:
        i, j, k = rec.int(0, "I"), rec.int(1, "J"), rec.int(2, "K", 0)
        ckt = rec.text(3)
        rec.what = f"transformer {i}-{j}" + (f"-{k}" if k else "") + f" ckt '{ckt}'"
        identity = (frozenset((i, j, k)), ckt.upper())
        if identity in self.transformer_lines:
            raise CaseError(f"{rec.what}: duplicate transformer (first at line "
                            f"{self.transformer_lines[identity]})", self.source, rec.line)
        self.transformer_lines[identity] = rec.line
        cw, cz, cm = rec.int(4, "CW", 1), rec.int(5, "CZ", 1), rec.int(6, "CM", 1)
        for name, code, allowed in (("CW", cw, (1, 2, 3)), ("CZ", cz, (1, 2, 3)),
                                    ("CM", cm, (1, 2))):
            if code not in allowed:
                raise CaseError(f"{rec.what}: {name} = {code}: must be one of {allowed}",
                                self.source, rec.line)
        status = rec.int(11, "STAT", 1)
        buses = (i, j, k) if k else (i, j)
        lines = [self._continuation(rec) for _ in range(len(buses) + 1)]
        imp, windings = lines[0], lines[1:]
        for bus in buses:
            if bus not in self.bus_rows:
                raise CaseError(f"{rec.what}: winding bus {bus} does not exist",
                                self.source, rec.line)
        g_mag, b_mag = self._magnetising(rec, cm, imp)
        ratios = [self._winding_ratio(w, cw, bus, n + 1) for n, (w, bus) in
                  enumerate(zip(windings, buses))]
        shifts = [math.radians(w.num(2, f"ANG{n + 1}", 0.0)) for n, w in enumerate(windings)]
        cod = 15 if self.layout >= 34 else 6  # after 12 ratings (v34+) or 3 (v30-v33)
        if any(w.int(cod, f"COD{n + 1}", 0) != 0 for n, w in enumerate(windings)):
            self.skipped["transformer tap control"] = self.skipped.get(
                "transformer tap control", 0) + 1
        if not k:
            r, x = self._pair_impedance(imp, cz, 0, "R1-2", "X1-2")
            t2 = ratios[1]
            self._add_transformer(rec, i, j, ckt, status != 0, r * t2 ** 2, x * t2 ** 2,
                                  ratios[0] / t2, shifts[0] - shifts[1], g_mag, b_mag)
            return
        z12 = complex(*self._pair_impedance(imp, cz, 0, "R1-2", "X1-2"))
        z23 = complex(*self._pair_impedance(imp, cz, 3, "R2-3", "X2-3"))
        z31 = complex(*self._pair_impedance(imp, cz, 6, "R3-1", "X3-1"))
        star_z = ((z12 + z31 - z23) / 2, (z12 + z23 - z31) / 2, (z23 + z31 - z12) / 2)
        self.star_count += 1
        star = -self.star_count
        on = [status not in (0, 4), status not in (0, 2), status not in (0, 3)]
        for n, z in enumerate(star_z):
            if abs(z) < THRSHZ:
                self.notes.append(f"{self.source}:{rec.line}: {rec.what}: star impedance of "
                                  f"winding {n + 1} is {abs(z):.1e} p.u., below THRSHZ; "
                                  "using X = 1e-4 p.u.")
        star_z = [z if abs(z) >= THRSHZ else THRSHZ * 1j for z in star_z]
        vm, va = imp.num(9, "VMSTAR", 1.0), math.radians(imp.num(10, "ANSTAR", 0.0))
        if (vm, va) == (1.0, 0.0):  # PSS/E's default, not a solved value
            vm, va = self._star_voltage(buses, star_z, ratios, shifts)
        winding1 = self.bus_rows[i]
        self.rows["buses"].append(dict(
            number=star, name=f"STAR {i}-{j}-{k} {ckt}", kind=1 if any(on) else ISOLATED,
            base_kv=winding1["base_kv"], area=winding1["area"], zone=winding1["zone"],
            vm=vm, va=va, line=rec.line))
        for n, bus in enumerate(buses):
            self._add_transformer(rec, bus, star, ckt, on[n], star_z[n].real, star_z[n].imag,
                                  ratios[n], shifts[n], g_mag if n == 0 else 0.0,
                                  b_mag if n == 0 else 0.0)

    def _star_voltage(self, buses, star_z, ratios, shifts) -> tuple[float, float]:
        """No-load star-point voltage from the windings' stored voltages: sum(y V) / sum(y)."""
        weights = [1 / z for z in star_z]
        volts = [self.bus_rows[b]["vm"] * cmath.exp(1j * (self.bus_rows[b]["va"] - shift)) / ratio
                 for b, ratio, shift in zip(buses, ratios, shifts)]
        v = sum(w * u for w, u in zip(weights, volts)) / sum(weights)
        return abs(v), cmath.phase(v)

    def _continuation(self, rec: _Record) -> _Record:
        number, text = self.cursor.next(f"{rec.what} (record starting at line {rec.line})")
        return _Record(split_fields(text), self.source, number, rec.what)

    def _winding_ratio(self, w: _Record, cw: int, bus: int, n: int) -> float:
        """Off-nominal ratio of winding `n`, p.u. of its bus base voltage."""
        windv = w.num(0, f"WINDV{n}", None if cw == 2 else 1.0)
        nomv = w.num(1, f"NOMV{n}", 0.0)
        base_kv = self.bus_rows[bus]["base_kv"]
        if cw != 1 and base_kv <= 0:
            raise CaseError(f"{w.what}: CW = {cw} needs the base kV of bus {bus}, "
                            f"which is {base_kv:g}", self.source, w.line)
        if cw == 1:
            ratio = windv
        elif cw == 2:
            ratio = windv / base_kv
        else:
            ratio = windv * (nomv or base_kv) / base_kv
        return self._check_ratio(w, f"WINDV{n}", ratio)

    def _check_ratio(self, rec: _Record, name: str, ratio: float) -> float:
        """`ratio` (p.u. of the bus base) if plausible, else CaseError naming field `name`."""
        reason = TAP_RATIO.problem(ratio)
        if reason:
            raise CaseError(f"{rec.what}: {name} gives an off-nominal ratio of {ratio:g}: "
                            f"{reason}", self.source, rec.line)
        return ratio

    def _pair_impedance(self, imp: _Record, cz: int, at: int, r_name: str, x_name: str):
        """Series impedance of one winding pair on the system base, p.u."""
        r, x = imp.num(at, r_name, 0.0), imp.num(at + 1, x_name)
        sbase = imp.num(at + 2, f"SBASE{r_name[1:]}", self.base_mva)
        if cz == 1:
            return r, x
        if sbase <= 0:
            raise CaseError(f"{imp.what}: SBASE{r_name[1:]} = {sbase:g}: must be > 0 MVA "
                            f"when CZ = {cz}", self.source, imp.line)
        if cz == 3:  # R: load loss in W; X: impedance magnitude, p.u. on winding base
            r = r / 1e6 / sbase
            x = math.sqrt(max(x * x - r * r, 0.0))
        scale = self.base_mva / sbase
        return r * scale, x * scale

    def _magnetising(self, rec: _Record, cm: int, imp: _Record) -> tuple[float, float]:
        mag1, mag2 = rec.num(7, "MAG1", 0.0), rec.num(8, "MAG2", 0.0)
        if cm == 1:
            return mag1, mag2
        g = mag1 / 1e6 / self.base_mva
        y = mag2 * imp.num(2, "SBASE1-2", self.base_mva) / self.base_mva
        return g, -math.sqrt(max(y * y - g * g, 0.0))

    def _add_transformer(self, rec, bus_from, bus_to, ckt, on, r, x, tap, shift, g, b) -> None:
        self.rows["branches"].append(dict(
            from_bus=bus_from, to_bus=bus_to, ckt=ckt, in_service=on, r=r, x=x, b=0.0,
            tap=tap, shift=shift, g_from=g, b_from=b, g_to=0.0, b_to=0.0,
            is_transformer=True, line=rec.line))

    # -- names ---------------------------------------------------------------
    def _area(self, rec: _Record) -> None:
        self.areas[rec.int(0, "I")] = rec.text(4, "")

    def _zone(self, rec: _Record) -> None:
        self.zones[rec.int(0, "I")] = rec.text(1, "")

    def _owner(self, rec: _Record) -> None:
        """Owner names are bookkeeping only."""

    def case(self, name: str) -> Case:
        skipped = dict(self.skipped)
        if skipped:
            listing = ", ".join(f"{k} x{v}" for k, v in skipped.items())
            warnings.warn(f"{self.source}: records not modelled, skipped: {listing}",
                          RawWarning, stacklevel=3)
        return build_case(
            name=name, source=self.source, base_mva=self.base_mva, frequency_hz=self.frequency,
            areas=self.areas, zones=self.zones, skipped=skipped, notes=self.notes,
            **self.rows)


def parse_raw(text: str, source: str = "<raw>", *, version: int | None = None,
              name: str | None = None) -> Case:
    """Parse RAW text into a validated `Case`; `version` overrides detection."""
    parser = _RawParser(text, source, version)
    parser.parse()
    return parser.case(name or Path(source).stem)


def raw_version(path: str | Path) -> int:
    """The RAW version (23, 30-35) of a file: its REV, else what its records imply."""
    path = Path(path)
    return _RawParser(path.read_text(encoding="utf-8", errors="replace"), str(path), None).version


def read_raw(path: str | Path, *, version: int | None = None) -> Case:
    """Read a PSS/E RAW file (v23, v30-v35) into a validated `Case`; `version` overrides the
    file's REV (or its absence)."""
    path = Path(path)
    text = path.read_text(encoding="utf-8", errors="replace")
    return parse_raw(text, str(path), version=version, name=path.stem)
