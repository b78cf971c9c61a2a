"""PSS/E RAW power-flow data reader: versions 23, 30 and 31-33.

Follows the record layouts of the PSS/E Program Operation Manual (POM),
"Power Flow Raw Data File Contents", for each revision:

- v23 (no REV field in the first line): loads and bus shunts live in the bus
  record (I, IDE, PL, QL, GL, BL, IA, VM, VA, NAME, BASKV, ZONE); transformers
  are branch records with a non-zero RATIO; tap-adjustment records follow.
- v30: bus (I, NAME, BASKV, IDE, GL, BL, AREA, ZONE, VM, VA, OWNER), separate
  load data, two- and three-winding transformer records of 4/5 lines.
- v31-v33: bus without GL/BL, a fixed-shunt section, switched shunts after FACTS.

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

SUPPORTED_VERSIONS = (23, 30, 31, 32, 33)

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
}
_LAYOUT = {23: 23, 30: 30, 31: 33, 32: 33, 33: 33}
# A file may end after these sections; stopping earlier means it is truncated.
_REQUIRED = {23: "branch", 30: "transformer", 33: "transformer"}
_LINES_PER_RECORD = {"two-terminal dc": 3, "vsc dc": 3}

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


def _detect_version(first: list[str], source: str) -> int:
    if len(first) < 3 or first[2] == "":
        return 23
    try:
        version = int(float(first[2]))
    except (ValueError, OverflowError):
        raise CaseError(f"case identification: REV = '{first[2]}' is not a number", source, 1)
    if version not in SUPPORTED_VERSIONS:
        raise CaseError(f"case identification: REV = {version}: RAW version not supported "
                        f"(supported: {', '.join(map(str, SUPPORTED_VERSIONS))})", source, 1)
    return version


class _RawParser:
    """Reads one RAW file into rows for `build_case`."""

    def __init__(self, text: str, source: str, version: int | None):
        self.source = source
        self.cursor = _Lines(text.lstrip("\ufeff"), source)
        _, first = self.cursor.next("case identification")
        head = _Record(split_fields(first), source, 1, "case identification")
        self.version = version or _detect_version(head.fields, source)
        self.layout = _LAYOUT[self.version]
        self.base_mva = head.num(1, "SBASE", 100.0, SYSTEM_BASE)
        self.frequency = 60.0 if self.version == 23 else head.num(
            5, "BASFRQ", 60.0, FREQUENCY) or 60.0
        self.cursor.next("case title")
        self.cursor.next("case title")
        self.rows: dict[str, list[dict[str, Any]]] = {
            k: [] for k in ("buses", "loads", "shunts", "generators", "branches")}
        self.areas: dict[int, str] = {}
        self.zones: dict[int, str] = {}
        self.skipped: dict[str, int] = {}
        self.notes: list[str] = []
        self.bus_rows: dict[int, dict[str, Any]] = {}
        self.star_count = 0
        self.transformer_lines: dict[tuple, int] = {}  # (buses, ckt) -> first line

    # -- driving -------------------------------------------------------------
    def parse(self) -> None:
        sections = _SECTIONS[self.layout]
        required = sections.index(_REQUIRED[self.layout])
        for k, section in enumerate(sections):
            if self.cursor.at_end():
                if k <= required:
                    raise CaseError(f"unexpected end of file before {section} data",
                                    self.source, len(self.cursor.lines))
                return
            if not self._section(section):
                return

    def _record_start(self, section: str) -> tuple[int, list[str]] | None:
        """Next record's first line, or None at the section's closing `0` line."""
        while True:
            number, text = self.cursor.next(
                f"{section} data (the section's closing '0' line is missing)")
            stripped = text.strip()
            if stripped.upper().startswith("Q"):
                return number, ["Q"]
            fields = split_fields(text)
            if not fields:
                continue
            if fields[0].strip() == "0":
                return None
            return number, fields

    def _section(self, section: str) -> bool:
        """Read one section; False when the file's `Q` end marker was met."""
        handler = getattr(self, "_" + section.replace(" ", "_").replace("-", "_"), None)
        while (start := self._record_start(section)) is not None:
            number, fields = start
            if fields == ["Q"]:
                return False
            record = _Record(fields, self.source, number, f"{section} record")
            if handler is None:
                self._skip(section, record)
            else:
                handler(record)
        return True

    def _skip(self, section: str, rec: _Record) -> None:
        """Count a record of a section not modelled and pass over its continuation lines (a
        multi-terminal dc record: one per converter, dc bus and dc link, NCONV + NDCBS +
        NDCLN)."""
        extra = _LINES_PER_RECORD.get(section, 1) - 1
        if section == "multi-terminal dc" and len(rec.fields) >= 4:
            extra = sum(rec.int(k, name, allowed=DC_COUNT)
                        for k, name in ((1, "NCONV"), (2, "NDCBS"), (3, "NDCLN")))
        for _ in range(extra):
            self.cursor.next(f"{section} data")
        self.skipped[section] = self.skipped.get(section, 0) + 1

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
        self._add_load(bus, load_id, rec.int(2, "STATUS", 1) != 0,
                       rec.num(5, "PL", 0.0), rec.num(6, "QL", 0.0), rec.num(7, "IP", 0.0),
                       rec.num(8, "IQ", 0.0), rec.num(9, "YP", 0.0), rec.num(10, "YQ", 0.0),
                       rec.line)

    def _fixed_shunt(self, rec: _Record) -> None:
        bus, shunt_id = rec.int(0, "I"), rec.text(1)
        rec.what = f"fixed shunt at bus {bus} id '{shunt_id}'"
        self._add_shunt(bus, shunt_id, rec.int(2, "STATUS", 1) != 0, rec.num(3, "GL", 0.0),
                        rec.num(4, "BL", 0.0), rec.line)

    def _switched_shunt(self, rec: _Record) -> None:
        bus = rec.int(0, "I")
        rec.what = f"switched shunt at bus {bus}"
        binit, status = {23: (5, None), 30: (7, None), 33: (9, 3)}[self.layout]
        on = True if status is None else rec.int(status, "STAT", 1) != 0
        self._add_shunt(bus, "sw", on, 0.0, rec.num(binit, "BINIT", 0.0), rec.line)

    def _generator(self, rec: _Record) -> None:
        bus, gen_id = rec.int(0, "I"), rec.text(1)
        rec.what = f"generator at bus {bus} id '{gen_id}'"
        s = self.base_mva
        mbase = rec.num(8, "MBASE", s)
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
            bus=bus, gen_id=gen_id, in_service=rec.int(14, "STAT", 1) != 0,
            pg=rec.num(2, "PG", 0.0) / s, qg=rec.num(3, "QG", 0.0) / s,
            qmax=qt / s, qmin=qb / s,
            vset=rec.num(6, "VS", 1.0, VOLTAGE), reg_bus=reg if reg != 0 else bus, mbase=mbase,
            zr=rec.num(9, "ZR", 0.0), zx=rec.num(10, "ZX", 1.0),
            pmax=rec.num(16, "PT", 9999.0) / s, pmin=rec.num(17, "PB", -9999.0) / s,
            line=rec.line))

    def _branch(self, rec: _Record) -> None:
        i, j, ckt = rec.int(0, "I"), abs(rec.int(1, "J")), rec.text(2)
        rec.what = f"branch {i}-{j} ckt '{ckt}'"
        if self.layout == 23:
            ratio, angle = rec.num(9, "RATIO", 0.0), rec.num(10, "ANGLE", 0.0)
            if ratio != 0:
                self._check_ratio(rec, "RATIO", ratio)
            gi, bi, gj, bj, st = 11, 12, 13, 14, 15
        else:
            ratio, angle = 0.0, 0.0
            gi, bi, gj, bj, st = 9, 10, 11, 12, 13
        self.rows["branches"].append(dict(
            from_bus=i, to_bus=j, ckt=ckt, in_service=rec.int(st, "ST", 1) != 0,
            r=rec.num(3, "R", 0.0), x=rec.num(4, "X"), b=rec.num(5, "B", 0.0),
            tap=ratio if ratio != 0 else 1.0, shift=math.radians(angle),
            g_from=rec.num(gi, "GI", 0.0), b_from=rec.num(bi, "BI", 0.0),
            g_to=rec.num(gj, "GJ", 0.0), b_to=rec.num(bj, "BJ", 0.0),
            is_transformer=ratio != 0, line=rec.line))

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
        if any(w.int(6, f"COD{n + 1}", 0) != 0 for n, w in enumerate(windings)):
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
            if abs(z) < 1e-4:  # PSS/E zero-impedance threshold THRSHZ
                self.notes.append(f"{self.source}:{rec.line}: {rec.what}: star impedance of "
                                  f"winding {n + 1} is {abs(z):.1e} p.u., below THRSHZ; "
                                  "using X = 1e-4 p.u.")
        star_z = [z if abs(z) >= 1e-4 else 1e-4j for z in star_z]
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
    """The RAW version (23, 30-33) of a file, from its case identification record."""
    path = Path(path)
    return _RawParser(path.read_text(encoding="utf-8", errors="replace"), str(path), None).version


def read_raw(path: str | Path, *, version: int | None = None) -> Case:
    """Read a PSS/E RAW file (v23, v30-v33) into a validated `Case`."""
    path = Path(path)
    text = path.read_text(encoding="utf-8", errors="replace")
    return parse_raw(text, str(path), version=version, name=path.stem)
