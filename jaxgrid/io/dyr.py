"""PSS/E dynamics data (DYR) reader.

Follows the dynamics data file layout of the PSS/E Program Operation Manual
(activity DYRE, "Dynamics Model Raw Data File"). Fields are free format,
separated by commas and/or blanks; character fields are quoted (single or
double quotes); a record ends at a ``/`` outside quotes and may span lines.
A line whose first non-blank characters are ``//`` is a comment. An ordinary
record is

    IBUS 'MODEL' ID CON(1) ... CON(n) /

and keeps every value after ID as a float CON (model-specific ICONs written
among the data, e.g. IEEEG1's JBUS and M, are left to the model layer).

User-written load models use

    IBUS 'USRLOD' LID 'NAME' IC IT NI NC NS NV NX ICON(1..NI) CON(1..NC) /

IC is the model type code (12 = load characteristic), IT the subsystem
(1 = single bus/load, 3 = zone), NI and NC the numbers of ICONs and CONs that
follow, NS and NV the STATE and VAR slots PSS/E reserves, NX (unverified)
internal ICON slots; no data follow for NS, NV and NX. 'USRMDL' records have
the same layout without NX (six header integers). The record's model is NAME.

Reader conventions beyond the manual: text after a ``/`` on the same line
starts another record when it begins with an integer (the next IBUS) and is a
trailing comment otherwise; a file may begin with a UTF-8 BOM; Fortran reals
such as ``0.33E-01``, ``5.``, ``-.5`` and ``1.0D-3`` are accepted.

The records it returns (`DyrRecord`, `DyrData`) are defined in `jaxgrid.records`, which the
device models import without this parser.
"""
from __future__ import annotations

import os
import re
import warnings
from collections.abc import Collection, Iterator
from dataclasses import dataclass

from jaxgrid.records import DyrData, DyrRecord

# Header integers of user-written records, by record type (see module docstring).
_USER_HEADERS = {
    "USRLOD": ("IC", "IT", "NI", "NC", "NS", "NV", "NX"),
    "USRMDL": ("IC", "IT", "NI", "NC", "NS", "NV"),
}

_TOKEN = re.compile(
    r"""'(?P<sq>[^']*)'|"(?P<dq>[^"]*)"|(?P<slash>/)|(?P<empty>,\s*(?=,))"""
    r"""|(?P<bare>[^\s,'"/]+)|(?P<open>['"])"""
)
_BAD_TOKENS = {"empty": "empty field between commas", "open": "unterminated quote"}
_INT = re.compile(r"[+-]?\d+")
_REAL = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[EeDd][+-]?\d+)?")


class DyrError(ValueError):
    """Malformed DYR data, or unsupported models in strict mode."""


class DyrWarning(UserWarning):
    """Unsupported models in lenient mode."""


@dataclass(frozen=True)
class _Token:
    text: str
    quoted: bool
    line: int


def read_dyr(
    path: str | os.PathLike[str],
    *,
    supported: Collection[str] | None = None,
    strict: bool = True,
) -> DyrData:
    """Read a DYR file; check its models against `supported` when given.

    Unsupported models raise one DyrError (strict) or give one DyrWarning;
    all records are kept either way.
    """
    source = os.fspath(path)
    with open(source, encoding="utf-8-sig", errors="replace") as f:
        text = f.read()
    records = tuple(_parse_record(tokens, source) for tokens in _split_records(text, source))
    unsupported = {} if supported is None else _check_supported(records, supported, source, strict)
    return DyrData(source=source, records=records, unsupported=unsupported)


def _fail(source: str, line: int, message: str) -> DyrError:
    return DyrError(f"{source}:{line}: {message}")


def _split_records(text: str, source: str) -> Iterator[list[_Token]]:
    """Token lists of the records (without the ending '/'), comments removed."""
    tokens: list[_Token] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if line.lstrip().startswith("//"):
            continue
        after_slash = False
        for m in _TOKEN.finditer(line):
            kind = m.lastgroup
            value = m.group(kind)
            if after_slash and not (kind == "bare" and _INT.fullmatch(value)):
                break  # text after '/' that does not start a record is a comment
            if kind in _BAD_TOKENS:
                raise _fail(source, lineno, _BAD_TOKENS[kind])
            after_slash = kind == "slash"
            if not after_slash:
                tokens.append(_Token(value, kind != "bare", lineno))
            elif tokens:
                yield tokens
                tokens = []
    if tokens:
        raise _fail(source, tokens[0].line, "record not terminated by '/'")


def _integer(tok: _Token, source: str, label: str, field: str) -> int:
    if tok.quoted or not _INT.fullmatch(tok.text):
        raise _fail(source, tok.line, f"{label}: {field} = {tok.text!r} is not an integer")
    return int(tok.text)


def _real(tok: _Token, source: str, label: str, field: str) -> float:
    if tok.quoted or not _REAL.fullmatch(tok.text):
        raise _fail(source, tok.line, f"{label}: {field} = {tok.text!r} is not a number")
    return float(tok.text.replace("D", "E").replace("d", "e"))


def _parse_record(tokens: list[_Token], source: str) -> DyrRecord:
    line = tokens[0].line
    if len(tokens) < 3:
        raise _fail(source, line, f"record has {len(tokens)} fields; needs IBUS, model name and ID")
    record_type = tokens[1].text.strip().upper()
    bus = _integer(tokens[0], source, f"{record_type} record", "IBUS")
    device_id = tokens[2].text.strip()
    if record_type.startswith("USR"):
        return _parse_user_record(tokens, source, record_type, bus, device_id)
    label = f"{record_type} at bus {bus} id {device_id!r}"
    cons = tuple(_real(t, source, label, f"CON({i})") for i, t in enumerate(tokens[3:], 1))
    return DyrRecord(model=record_type, bus=bus, device_id=device_id, cons=cons, icons=(),
                     header=(), record_type=record_type, line=line, source=source)


def _parse_user_record(
    tokens: list[_Token], source: str, record_type: str, bus: int, device_id: str
) -> DyrRecord:
    line = tokens[0].line
    names = _USER_HEADERS.get(record_type)
    if names is None:
        raise _fail(source, line, f"user record type {record_type} at bus {bus}: layout not known "
                                  f"(known: {', '.join(_USER_HEADERS)})")
    n = len(names)
    if len(tokens) < 4 + n:
        raise _fail(source, line, f"{record_type} record at bus {bus} id {device_id!r}: "
                                  f"model name and {n} header integers expected")
    model = tokens[3].text.strip().upper()
    label = f"{model} ({record_type}) at bus {bus} id {device_id!r}"
    header = tuple(_integer(t, source, label, name) for t, name in zip(tokens[4:], names))
    ni, nc = header[2], header[3]
    values = tokens[4 + n:]
    if len(values) != ni + nc:
        raise _fail(source, line, f"{label}: header says {n}+NI+NC = {n}+{ni}+{nc} = {n + ni + nc} "
                                  f"values after the model name, found {n + len(values)}")
    icons = tuple(t.text.strip() if t.quoted else _integer(t, source, label, f"ICON({i})")
                  for i, t in enumerate(values[:ni], 1))
    cons = tuple(_real(t, source, label, f"CON({i})") for i, t in enumerate(values[ni:], 1))
    return DyrRecord(model=model, bus=bus, device_id=device_id, cons=cons, icons=icons,
                     header=header, record_type=record_type, line=line, source=source)


def _check_supported(
    records: tuple[DyrRecord, ...], supported: Collection[str], source: str, strict: bool
) -> dict[str, int]:
    """Count unsupported models; raise (strict) or warn once when there are any."""
    allowed = {name.upper() for name in supported}
    counts: dict[str, int] = {}
    first: dict[str, int] = {}
    for r in records:
        if r.model not in allowed:
            counts[r.model] = counts.get(r.model, 0) + 1
            first.setdefault(r.model, r.line)
    if counts:
        listing = ", ".join(f"{m} x{n} (first at line {first[m]})" for m, n in counts.items())
        plural = "s" if len(counts) > 1 else ""
        message = f"{source}: {len(counts)} unsupported dynamic model{plural}: {listing}"
        if strict:
            raise DyrError(message)
        warnings.warn(message, DyrWarning, stacklevel=3)
    return counts
