"""Validated, host-side description of a power network.

A `Case` is plain NumPy data: every quantity is per unit on the system base
(`base_mva`), angles are radians, and buses are addressed by an internal index
0..n_bus-1 (the order of the source file). External bus numbers are kept in
`Case.buses.number`. Readers (`jaxgrid.io.raw`, `jaxgrid.io.matpower`) produce
*rows* that still carry external bus numbers and source line numbers;
`build_case` maps the numbers to indices and validates, so every error names
the file, the line, the record, the field and the bad value:

    case.raw:123: branch 4-5 ckt '1': to bus 5 does not exist

Conventions (consumption positive for loads, injection positive for shunts):
- load P/Q are consumed at 1 p.u. voltage, split into constant power, constant
  current and constant admittance parts (PSS/E PL/QL, IP/IQ, YP/-YQ);
- shunt g + jb is the admittance to ground (b > 0 capacitive);
- a branch is a pi model with an ideal transformer of complex ratio
  tap * exp(j shift) on the from side (MATPOWER's model), plus bus-side shunts
  at either end (PSS/E line shunts GI/BI, GJ/BJ, transformer magnetising
  admittance at the winding-1 bus).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from jaxgrid.checks import Range

PQ, PV, SLACK, ISOLATED = 1, 2, 3, 4  # PSS/E bus type codes (IDE)
TAP_RATIO = Range(0.1, 10.0, "p.u.")  # plausible off-nominal transformer ratios
VOLTAGE = Range(0.0, 2.0, "p.u.", lo_open=True, hi_open=True)  # voltage set points and levels


class CaseError(ValueError):
    """Bad input data; the message starts with `source:line:` when known."""

    def __init__(self, message: str, source: str | None = None, line: int | None = None):
        prefix = ""
        if source:
            prefix = f"{source}:{line}: " if line else f"{source}: "
        super().__init__(prefix + message)
        self.source, self.line = source, line


@dataclasses.dataclass(frozen=True)
class Buses:
    """Buses, in source-file order.

    Attributes:
      number: (n_bus,) external bus numbers.
      name: (n_bus,) bus names.
      kind: (n_bus,) PSS/E type: 1 PQ, 2 PV, 3 slack, 4 isolated (out of service).
      base_kv: (n_bus,) nominal voltage, kV.
      area, zone: (n_bus,) area and zone numbers.
      vm: (n_bus,) stored voltage magnitude, p.u.
      va: (n_bus,) stored voltage angle, radians.
      line: (n_bus,) source line of each record (0 if none).
    """

    number: np.ndarray
    name: tuple[str, ...]
    kind: np.ndarray
    base_kv: np.ndarray
    area: np.ndarray
    zone: np.ndarray
    vm: np.ndarray
    va: np.ndarray
    line: np.ndarray


@dataclasses.dataclass(frozen=True)
class Loads:
    """Load records (several per bus allowed). Powers consumed at 1 p.u. voltage, p.u.

    Attributes:
      bus: (n_load,) internal bus index.
      load_id: (n_load,) PSS/E load identifier.
      in_service: (n_load,) bool.
      p_power, q_power: (n_load,) constant-power part (PL, QL).
      p_current, q_current: (n_load,) constant-current part (IP, IQ; Q > 0 inductive).
      p_impedance, q_impedance: (n_load,) constant-admittance part (YP, -YQ;
        PSS/E stores YQ negative for inductive load, here Q > 0 is inductive).
      line: (n_load,) source line.
    """

    bus: np.ndarray
    load_id: tuple[str, ...]
    in_service: np.ndarray
    p_power: np.ndarray
    q_power: np.ndarray
    p_current: np.ndarray
    q_current: np.ndarray
    p_impedance: np.ndarray
    q_impedance: np.ndarray
    line: np.ndarray


@dataclasses.dataclass(frozen=True)
class Shunts:
    """Shunt admittances to ground at 1 p.u. voltage, p.u. (b > 0 capacitive).

    Attributes:
      bus: (n_shunt,) internal bus index.
      shunt_id: (n_shunt,) identifier ("bus" for PSS/E v23/v30 bus GL/BL,
        "sw" for switched shunts, fixed at their stored value).
      in_service: (n_shunt,) bool.
      g, b: (n_shunt,) conductance and susceptance, p.u.
      line: (n_shunt,) source line.
    """

    bus: np.ndarray
    shunt_id: tuple[str, ...]
    in_service: np.ndarray
    g: np.ndarray
    b: np.ndarray
    line: np.ndarray


@dataclasses.dataclass(frozen=True)
class Generators:
    """Generator records.

    Attributes:
      bus: (n_gen,) internal bus index.
      gen_id: (n_gen,) machine identifier.
      in_service: (n_gen,) bool.
      pg, qg: (n_gen,) stored output, p.u. system base.
      qmax, qmin: (n_gen,) reactive limits, p.u. system base.
      pmax, pmin: (n_gen,) active limits, p.u. system base.
      vset: (n_gen,) voltage set point, p.u.
      reg_bus: (n_gen,) internal index of the regulated bus.
      mbase: (n_gen,) machine base, MVA.
      zr, zx: (n_gen,) source impedance (ZSORCE), p.u. on mbase.
      line: (n_gen,) source line.
    """

    bus: np.ndarray
    gen_id: tuple[str, ...]
    in_service: np.ndarray
    pg: np.ndarray
    qg: np.ndarray
    qmax: np.ndarray
    qmin: np.ndarray
    pmax: np.ndarray
    pmin: np.ndarray
    vset: np.ndarray
    reg_bus: np.ndarray
    mbase: np.ndarray
    zr: np.ndarray
    zx: np.ndarray
    line: np.ndarray


@dataclasses.dataclass(frozen=True)
class Branches:
    """Lines and transformers as pi models, p.u. on the system base.

    Three-winding transformers appear as three branches to a star bus.

    Attributes:
      from_bus, to_bus: (n_branch,) internal bus indices.
      ckt: (n_branch,) circuit identifier.
      in_service: (n_branch,) bool.
      r, x: (n_branch,) series impedance, p.u.
      b: (n_branch,) total line charging, p.u. (half at each end, inside the tap).
      tap: (n_branch,) off-nominal ratio magnitude on the from side (1 for lines).
      shift: (n_branch,) phase shift, radians (from-side voltage leads).
      g_from, b_from, g_to, b_to: (n_branch,) bus-side shunts at each end, p.u.
      is_transformer: (n_branch,) bool.
      line: (n_branch,) source line.
    """

    from_bus: np.ndarray
    to_bus: np.ndarray
    ckt: tuple[str, ...]
    in_service: np.ndarray
    r: np.ndarray
    x: np.ndarray
    b: np.ndarray
    tap: np.ndarray
    shift: np.ndarray
    g_from: np.ndarray
    b_from: np.ndarray
    g_to: np.ndarray
    b_to: np.ndarray
    is_transformer: np.ndarray
    line: np.ndarray


@dataclasses.dataclass(frozen=True)
class Case:
    """A validated network: tables above plus identification and import report.

    Attributes:
      name: case name.
      source: file (or package reference) it was read from.
      base_mva: system base, MVA.
      frequency_hz: nominal frequency, Hz.
      areas, zones: number -> name.
      skipped: record kind -> count of records the reader did not model.
      notes: what the reader changed or defaulted (the load report).
    """

    name: str
    source: str
    base_mva: float
    frequency_hz: float
    buses: Buses
    loads: Loads
    shunts: Shunts
    generators: Generators
    branches: Branches
    areas: dict[int, str] = dataclasses.field(default_factory=dict)
    zones: dict[int, str] = dataclasses.field(default_factory=dict)
    skipped: dict[str, int] = dataclasses.field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def n_bus(self) -> int:
        return len(self.buses.number)

    def bus_index(self, numbers: int | Sequence[int]) -> np.ndarray:
        """Internal indices of external bus numbers; KeyError names a missing one."""
        lookup = {int(n): i for i, n in enumerate(self.buses.number)}
        numbers = np.atleast_1d(np.asarray(numbers))
        missing = [int(n) for n in numbers if int(n) not in lookup]
        if missing:
            raise KeyError(f"{self.name}: no bus numbered {missing}")
        return np.array([lookup[int(n)] for n in numbers], dtype=np.int64)


# --------------------------------------------------------------------------- #
# Building a case from reader rows
# --------------------------------------------------------------------------- #

_INTERNAL_BUS_FIELDS = {
    Loads: ("bus",),
    Shunts: ("bus",),
    Generators: ("bus", "reg_bus"),
    Branches: ("from_bus", "to_bus"),
}
_BUS_FIELD_LABELS = {"bus": "bus", "reg_bus": "regulated bus (IREG)", "from_bus": "from bus",
                     "to_bus": "to bus"}


def _table(cls, rows: list[dict[str, Any]]):
    """Column-stack `rows` (dicts keyed by field name) into dataclass `cls`."""
    columns = {}
    for field in dataclasses.fields(cls):
        values = [row[field.name] for row in rows]
        if field.type.startswith("tuple"):
            columns[field.name] = tuple(str(v) for v in values)
        else:
            columns[field.name] = np.asarray(values) if values else np.zeros(0)
    for name in ("in_service", "is_transformer"):
        if name in columns:
            columns[name] = columns[name].astype(bool)
    for name in ("number", "kind", "area", "zone", "line", *_INTERNAL_BUS_FIELDS.get(cls, ())):
        if name in columns:
            columns[name] = columns[name].astype(np.int64)
    return cls(**columns)


def _describe(kind: str, row: dict[str, Any]) -> str:
    """Human-readable record name for error messages, with external numbers."""
    if kind == "branch":
        return f"branch {row['from_bus']}-{row['to_bus']} ckt '{row['ckt']}'"
    if kind == "generator":
        return f"generator at bus {row['bus']} id '{row['gen_id']}'"
    if kind == "load":
        return f"load at bus {row['bus']} id '{row['load_id']}'"
    return f"shunt at bus {row['bus']} id '{row['shunt_id']}'"


def build_case(
    *,
    name: str,
    source: str,
    base_mva: float,
    frequency_hz: float,
    buses: list[dict[str, Any]],
    loads: list[dict[str, Any]],
    shunts: list[dict[str, Any]],
    generators: list[dict[str, Any]],
    branches: list[dict[str, Any]],
    areas: dict[int, str] | None = None,
    zones: dict[int, str] | None = None,
    skipped: dict[str, int] | None = None,
    notes: Sequence[str] = (),
) -> Case:
    """Map external bus numbers to indices, stack rows into tables and validate.

    Rows are dicts keyed by the field names of the tables above, with external
    bus numbers in the bus fields and the source line in `line`.
    Raises CaseError (file:line: record: field = value: reason).
    """
    if not base_mva > 0:
        raise CaseError(f"system base SBASE = {base_mva}: must be > 0 MVA", source, 1)
    index: dict[int, int] = {}
    for i, row in enumerate(buses):
        number = int(row["number"])
        if number in index:
            raise CaseError(f"bus {number}: duplicate bus number", source, row["line"])
        index[number] = i
    if not buses:
        raise CaseError("no bus records", source)
    _check_identities(source, generators, loads, branches)

    def resolve(kind, rows, cls):
        resolved = []
        for row in rows:
            for field in _INTERNAL_BUS_FIELDS[cls]:
                number = int(row[field])
                if number not in index:
                    raise CaseError(
                        f"{_describe(kind, row)}: {_BUS_FIELD_LABELS[field]} {number} "
                        "does not exist", source, row["line"])
            resolved.append({**row, **{field: index[int(row[field])]
                                       for field in _INTERNAL_BUS_FIELDS[cls]}})
        return _table(cls, resolved)

    case = Case(
        name=name, source=source, base_mva=float(base_mva), frequency_hz=float(frequency_hz),
        buses=_table(Buses, buses),
        loads=resolve("load", loads, Loads),
        shunts=resolve("shunt", shunts, Shunts),
        generators=resolve("generator", generators, Generators),
        branches=resolve("branch", branches, Branches),
        areas=dict(areas or {}), zones=dict(zones or {}),
        skipped=dict(skipped or {}), notes=tuple(notes),
    )
    validate(case)
    return case


def _check_identities(source, generators, loads, branches) -> None:
    """CaseError at the second record with the identity of an earlier one, as PSS/E rejects
    them: generators and loads by (bus, ID), lines and transformers each by (buses, circuit)."""
    def ident(text) -> str:
        return str(text).strip().upper()

    tables = (
        ("generator", generators, lambda r: (int(r["bus"]), ident(r["gen_id"]))),
        ("load", loads, lambda r: (int(r["bus"]), ident(r["load_id"]))),
        ("branch", branches, lambda r: (bool(r["is_transformer"]), frozenset(
            (int(r["from_bus"]), int(r["to_bus"]))), ident(r["ckt"]))),
    )
    for kind, rows, key in tables:
        first_line: dict = {}
        for row in rows:
            k = key(row)
            if k in first_line:
                what = "transformer" if kind == "branch" and row["is_transformer"] else kind
                raise CaseError(f"{_describe(kind, row)}: duplicate {what} (the same "
                                f"identity as line {first_line[k]})", source, row["line"])
            first_line[k] = row["line"]


def _check_branch_impedance(case: Case) -> None:
    br = case.branches
    zero = (br.r == 0) & (br.x == 0)
    for k in np.flatnonzero(zero | ~np.isfinite(br.r) | ~np.isfinite(br.x)):
        number = case.buses.number
        raise CaseError(
            f"branch {number[br.from_bus[k]]}-{number[br.to_bus[k]]} ckt '{br.ckt[k]}': "
            f"X = {br.x[k]:g}, R = {br.r[k]:g}: zero or non-finite series impedance "
            "is not supported (give the jumper a small reactance, e.g. X = 1e-4)",
            case.source, int(br.line[k]))
    for k, tap in enumerate(br.tap):
        reason = TAP_RATIO.problem(tap)
        if reason:
            raise CaseError(
                f"transformer {case.buses.number[br.from_bus[k]]}-"
                f"{case.buses.number[br.to_bus[k]]} ckt '{br.ckt[k]}': ratio = {tap:g}: "
                f"{reason}", case.source, int(br.line[k]))


def islands(case: Case) -> tuple[int, np.ndarray]:
    """Connected components over in-service branches: (count, (n_bus,) label)."""
    br = case.branches
    on = br.in_service & (case.buses.kind[br.from_bus] != ISOLATED) & (
        case.buses.kind[br.to_bus] != ISOLATED)
    graph = coo_matrix(
        (np.ones(int(on.sum())), (br.from_bus[on], br.to_bus[on])),
        shape=(case.n_bus, case.n_bus))
    return connected_components(graph, directed=False)


def validate(case: Case) -> None:
    """Raise CaseError for data the power flow cannot use.

    Checks: finite non-zero branch impedances and positive ratios; at least one
    slack bus; every in-service bus connected to a slack bus (an island without
    a slack, e.g. a bus whose branches are all out of service, is an error:
    mark such buses isolated, type 4).
    """
    _check_branch_impedance(case)
    active = case.buses.kind != ISOLATED
    slack = case.buses.kind == SLACK
    if not slack.any():
        raise CaseError("no slack bus (a bus of type 3) in the case", case.source)
    _, label = islands(case)
    slack_islands = set(label[slack].tolist())
    stranded = np.flatnonzero(active & ~np.isin(label, list(slack_islands)))
    if stranded.size:
        first = int(stranded[0])
        numbers = case.buses.number[stranded][:10].tolist()
        more = f" and {stranded.size - 10} more" if stranded.size > 10 else ""
        raise CaseError(
            f"bus {case.buses.number[first]}: islanded, no in-service path to a slack bus "
            f"(buses {numbers}{more}); mark them type 4 or connect them",
            case.source, int(case.buses.line[first]))


def to_rows(case: Case) -> dict[str, Any]:
    """The inverse of `build_case`: keyword arguments (rows with external bus numbers).

    Lets a builder edit a case (add buses, move loads) and rebuild it validated.
    """
    number = case.buses.number

    def rows(table, bus_fields=()):
        fields = [f.name for f in dataclasses.fields(table)]
        columns = {name: getattr(table, name) for name in fields}
        out = []
        for k in range(len(table.line)):
            row = {name: columns[name][k] for name in fields}
            for name in bus_fields:
                row[name] = int(number[row[name]])
            out.append(row)
        return out

    return dict(
        name=case.name, source=case.source, base_mva=case.base_mva,
        frequency_hz=case.frequency_hz, buses=rows(case.buses),
        loads=rows(case.loads, _INTERNAL_BUS_FIELDS[Loads]),
        shunts=rows(case.shunts, _INTERNAL_BUS_FIELDS[Shunts]),
        generators=rows(case.generators, _INTERNAL_BUS_FIELDS[Generators]),
        branches=rows(case.branches, _INTERNAL_BUS_FIELDS[Branches]),
        areas=case.areas, zones=case.zones, skipped=case.skipped, notes=case.notes)


LOAD_POWER_FIELDS = ("p_power", "q_power", "p_current", "q_current", "p_impedance",
                     "q_impedance")  # every ZIP part of a load (p.u.)


def at_load_level(case: Case, level: float, name: str, source: str) -> Case:
    """`case` with every load (P and Q, all ZIP parts) and every generator's P dispatch
    times `level`, renamed `name` from `source`; the slack takes the change in losses when
    its power flow is solved. Machine data and reactive limits are unchanged."""
    rows = to_rows(case)
    for load in rows["loads"]:
        for key in LOAD_POWER_FIELDS:
            load[key] = load[key] * level
    for gen in rows["generators"]:
        gen["pg"] = gen["pg"] * level
    rows.update(name=name, source=source)
    return build_case(**rows)
