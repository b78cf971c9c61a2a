"""Compile a solved case and its DYR records into a `GridModel`.

Host side, NumPy and float64: match dynamic records to generators and load records, read
and check their CONs, initialise every device from the power flow in the order machines
-> exciters -> governors (spec §0), then load models (motors; what they do not draw of
their bus's load stays static), fold machines' and motors' Norton admittances and
constant-admittance loads into the network matrix and invert it, then check that all
derivatives vanish at t = 0.
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrid import network
from jaxgrid.case import ISOLATED, PQ, Case
from jaxgrid.dynamics import FAMILIES, derivatives, update_loads
from jaxgrid.grid import DeviceGroup, GridModel, GridState
from jaxgrid.io.dyr import DyrError
from jaxgrid.models.acmotor import LOAD_MOTORS
from jaxgrid.models.base import (Initial, LoadSite, ModelError, Signals, StartPoint,
                                 device_label)
from jaxgrid.models.cmld import COMPOSITE_LOADS, composite_records, read_records, run_model
from jaxgrid.models.cmld_init import expand
from jaxgrid.models.exciters import EXCITERS
from jaxgrid.models.governors import GOVERNORS
from jaxgrid.models.induction import INDUCTION_MOTORS
from jaxgrid.models.loads import LoadSplit, split_bus_loads
from jaxgrid.models.machines import MACHINES
from jaxgrid.models.options import CompositeOptions, MotorOptions
from jaxgrid.models.stabilizers import STABILIZERS
from jaxgrid.powerflow import PowerFlowResult, admittance_matrix, bus_loads, solve
from jaxgrid.records import DyrData, DyrRecord

LOAD_MODELS = {**LOAD_MOTORS, **INDUCTION_MOTORS}
SUPPORTED = (tuple(MACHINES) + tuple(EXCITERS) + tuple(GOVERNORS) + tuple(STABILIZERS)
             + tuple(LOAD_MODELS) + tuple(COMPOSITE_LOADS))

# What replaces a model that is not supported, by kind (lenient mode).
_FALLBACK = {
    "stabilizer": "the exciter runs without a stabilizer signal",
    "load": "the load stays a static ZIP load (CompileOptions.loads)",
    "exciter": "the machine keeps its initial field voltage",
    "governor": "the machine keeps its initial mechanical power",
    "machine": "the generator becomes a constant-admittance negative load",
}
_KINDS = {
    "stabilizer": {"IEEEST", "ST2CUT", "PSS1A", "PSS2A", "PSS2B", "PSS3B", "STAB1", "STAB2",
                   "STAB3", "STAB4", "IEE2ST", "STBSVC"},
    "load": {"CIM5BL", "CIM6BL", "CIMWBL", "CLODBL", "CMLDBLU1", "CMLDBLU2", "IEELBL",
             "LDFRBL", "ACMTBLU1", "CMLDARU2", "CMLDOWU2", "CMLDZNU2"},
    "exciter": {"ESAC1A", "ESAC2A", "ESAC3A", "ESAC4A", "ESAC5A", "ESAC6A", "ESAC8B", "ESDC2A",
                "ESST1A", "ESST2A", "ESST4B", "EXAC1", "EXAC2", "EXAC3", "EXAC4", "EXPIC1",
                "SCRX", "IEEET2", "IEEET3", "IEEET4", "IEEEX2", "IEEEX3", "IEEEX4", "EXBAS",
                "EXELI", "EXNI", "REXS", "URST5T", "AC8B"},
    "governor": {"GGOV1", "WSIEG1", "TGOV5", "HYGOV4", "IEEEG2", "IEEEG3", "GAST2A", "WEHGOV",
                 "WSHYGP", "WPIDHY", "TGOV3", "PIDGOV", "DEGOV1", "HYGOVM", "WESGOV"},
    "machine": {"GENTPJ", "GENTPF", "GENDCO", "CGEN1", "FRECHG", "CSVGN1", "REGCA1", "REGCB1"},
}


MACHINE_BASE_RULES = ("gridpack", "raw")  # CompileOptions.machine_base
GRIDPACK_RESIZED = ("GENSAL", "GENROU")  # the machine models GridPACK re-bases when overloaded
MBASE_MARGIN = 1.2  # GridPACK's new MBASE over the machine's loading
INIT_SWEEPS = 2  # network sweeps of the check that every device starts at rest (Solver's default)


class ModelWarning(UserWarning):
    """Dynamic data dropped or approximated: unsupported models and records naming no
    generator (lenient mode), and every model's notes."""


class InitWarning(UserWarning):
    """A device starts away from equilibrium or outside a limit."""


@dataclasses.dataclass(frozen=True)
class CompileOptions:
    """How a case becomes a `GridModel`.

    Attributes:
      strict: unsupported DYR models (or a generator with dynamic records but no machine
        model) raise a DyrError listing all of them; otherwise they are dropped with one
        warning that says what replaces each. A generator the DYR data do not mention is a
        constant-admittance negative load either way (noted).
      loads: ZIP split of static loads during dynamics (default: constant admittance).
      load_buses: RAW bus numbers whose load can be changed (load shedding); None: every
        bus with an in-service load. Buses with a load model always get a slot.
      motors: readings of motor-load data where reference simulators disagree.
      composite: readings of the WECC composite load (CMLDBLU1/2) data.
      precision: "float32" (default time loop) or "float64".
      machine_base: "gridpack" (default) or "raw", where the power flow loads a GENSAL or
        GENROU beyond its MBASE ([choice], `machine_bases`).
      init_tolerance: largest |derivative| at t = 0 accepted without an InitWarning.
    """

    strict: bool = True
    loads: LoadSplit = LoadSplit()
    load_buses: tuple[int, ...] | None = None
    motors: MotorOptions = MotorOptions()
    composite: CompositeOptions = CompositeOptions()
    precision: str = "float32"
    init_tolerance: float = 1e-5
    machine_base: str = "gridpack"

    def __post_init__(self):
        if self.machine_base not in MACHINE_BASE_RULES:
            raise ValueError(f"machine_base = {self.machine_base!r}: allowed "
                             f"{', '.join(MACHINE_BASE_RULES)}")
        if self.precision not in ("float32", "float64"):
            raise ValueError(f"precision = {self.precision!r}: allowed 'float32' or 'float64'")


def compile_model(case: Case, dyr: DyrData, options: CompileOptions = CompileOptions(),
                  pf: PowerFlowResult | None = None) -> GridModel:
    """A GridModel for `case` at its power-flow point with the dynamic models of `dyr`.

    Composite loads (CMLDBLU1/2) start with the other load models at their system buses,
    then add their low-side and load buses to the case (`jaxgrid.models.cmld_init.expand`);
    the model's buses are then the RAW buses followed by those internal buses, named in
    `GridModel.bus_names`.

    Raises DyrError (unsupported models, strict) or ModelError (bad CONs, naming file,
    line, device and field); warns InitWarning when a device does not start at rest.
    """
    pf = solve(case) if pf is None else pf
    notes: list[str] = []
    records = _classify(dyr, case, options.strict, notes)
    notes.extend(_sentinel_notes(records))
    keys, load_keys = _unit_keys(case)
    machines = _machine_groups(case, records["machine"], keys, options.strict, notes,
                               {_key(r) for rs in records.values() for r in rs})
    order = np.array([u for g in machines for u in g.units], dtype=int)
    position = {int(g): k for k, g in enumerate(order)}
    pending = {"machines": machines,
               "exciters": _controller_groups(case, records["exciter"], EXCITERS, keys, position),
               "governors": _controller_groups(case, records["governor"], GOVERNORS, keys,
                                               position),
               "loads": _load_groups(records["load"], load_keys, options.composite),
               "stabilizers": _controller_groups(case, records["stabilizer"], STABILIZERS,
                                                 keys, position)}
    _note_idle_stabilizers(pending, notes)

    gen = case.generators
    sbase = case.base_mva
    ratio = machine_bases(case, pf, machines, order, options.machine_base, notes) / sbase
    vt0 = (pf.vm * np.exp(1j * pf.va))[gen.bus[order]]
    i0 = np.conj((pf.pg[order] + 1j * pf.qg[order]) / ratio / vt0)  # machine base
    bus_p = _bus_load_at(_without_composite(case, pending["loads"]), pf).real
    started, point = _start(pending, _start_point(case, pf, vt0, i0, bus_p, ratio * sbase,
                                                  options))
    machines, m_states = _device_groups(started["machines"])
    exciters, e_states = _device_groups(started["exciters"])
    governors, g_states = _device_groups(started["governors"])
    stabilizers, s_states = _device_groups(started["stabilizers"])
    efd0, pm0 = (np.asarray(a) for a in (point.signals.efd, point.signals.pm))

    case, pf, loads, names, upstream = _expand(case, pf, records["load"], started["loads"],
                                               options.composite, notes)
    v0 = pf.vm * np.exp(1j * pf.va)
    on = gen.in_service & (case.buses.kind[gen.bus] != ISOLATED)
    z_source = np.concatenate([g.params["ra"] + 1j * g.params["xs"] for g in machines])
    y_norton = ratio / z_source
    s_load = _bus_load_at(case, pf)
    motors = _load_units(case, loads, s_load.real, notes)
    s_static = s_load.copy()
    for m in motors:
        np.add.at(s_static, m.buses, -m.s0)
    y_z, s_i, s_p = split_bus_loads(s_static, v0, options.loads)
    y = admittance_matrix(case)
    y[np.diag_indices(case.n_bus)] += y_z + _unmodelled_admittance(case, pf, on, order, notes)
    np.add.at(y, (gen.bus[order], gen.bus[order]), y_norton)
    for m in motors:
        np.add.at(y, (m.buses, m.buses), m.params["y_norton"])
    load_bus = _load_buses(case, s_load, options,
                           [b for m in motors for b in m.buses] + upstream.tolist())
    slot_bus = np.concatenate([gen.bus[order], load_bus]).astype(int)
    slot_of = {int(b): k for k, b in enumerate(load_bus)}
    if upstream.size:
        motors[-1].params["upstream_slot"] = np.array([slot_of[int(b)] for b in upstream])
    load_groups = tuple(
        DeviceGroup(params=m.params, model=m.model, index=tuple(slot_of[int(b)] for b in m.buses),
                    labels=m.labels) for m in motors)
    _report_model_notes(case, machines + exciters + governors + stabilizers + load_groups, notes)

    model = GridModel(
        machines=machines, exciters=exciters, governors=governors, loads=load_groups,
        stabilizers=stabilizers,
        network=network.build(y, slot_bus, np.complex128),
        z_source=z_source, y_norton=y_norton, mbase_ratio=ratio, efd0=efd0, pm0=pm0,
        load_y=y_z[load_bus], load_s_i=s_i[load_bus], load_s_p=s_p[load_bus],
        load_vm0=np.maximum(pf.vm[load_bus], 1e-6), load_p0=s_load[load_bus].real, v0=v0,
        initial=GridState(machines=m_states, exciters=e_states, governors=g_states,
                          stabilizers=s_states, loads=tuple(m.states for m in motors),
                          load_flags=tuple(m.flags for m in motors),
                          load_left=np.ones(len(load_bus)), v=v0[slot_bus]),
        bus_numbers=tuple(int(b) for b in case.buses.number),
        bus_names=tuple(names.get(int(b), f"Bus{b}") for b in case.buses.number),
        gen_bus=tuple(int(case.buses.number[gen.bus[g]]) for g in order),
        gen_id=tuple(gen.gen_id[g].strip() for g in order),
        slot_bus=tuple(int(b) for b in slot_bus), load_bus=tuple(int(b) for b in load_bus),
        omega_b=float(2 * np.pi * case.frequency_hz), pq_break=options.loads.pq_break,
        precision="float64", notes=())
    _check_initial_state(model, options.init_tolerance, notes)
    _check_values(model, options.precision)
    return with_precision(dataclasses.replace(model, notes=tuple(notes)), options.precision)


def with_precision(model: GridModel, precision: str) -> GridModel:
    """The same model with its arrays cast to float32/complex64 or float64/complex128."""
    real, cplx = (np.float64, np.complex128) if precision == "float64" else (np.float32,
                                                                            np.complex64)

    def cast(a):
        a = np.asarray(a)
        if np.iscomplexobj(a):
            return a.astype(cplx)
        return a.astype(real) if np.issubdtype(a.dtype, np.floating) else a

    return dataclasses.replace(jax.tree.map(cast, model), precision=precision)


# --------------------------------------------------------------------------- #
# Records -> device groups
# --------------------------------------------------------------------------- #

def _key(record: DyrRecord) -> tuple[int, str]:
    return record.bus, record.device_id.strip().upper()


def _unit_keys(case: Case) -> tuple[dict, dict]:
    """{(bus number, ID): index} of in-service machines (on live buses) and loads."""
    gen, loads, number = case.generators, case.loads, case.buses.number
    on = gen.in_service & (case.buses.kind[gen.bus] != ISOLATED)
    keys = {(int(number[gen.bus[k]]), gen.gen_id[k].strip().upper()): int(k)
            for k in np.flatnonzero(on)}
    load_keys = {(int(number[loads.bus[k]]), loads.load_id[k].strip().upper()): int(k)
                 for k in np.flatnonzero(loads.in_service)}
    return keys, load_keys


def _kind(name: str) -> str:
    if name in MACHINES or name in _KINDS["machine"]:
        return "machine"
    if name in EXCITERS or name in _KINDS["exciter"]:
        return "exciter"
    if name in GOVERNORS or name in _KINDS["governor"]:
        return "governor"
    for kind in ("stabilizer", "load"):
        if name in _KINDS[kind]:
            return kind
    return "other"


def _classify(dyr: DyrData, case: Case, strict: bool, notes: list[str]) -> dict[str, list]:
    """Supported records by kind. Unsupported ones, and records naming a generator or load
    record the case does not have (or has out of service: loads), raise (strict, listing all)
    or are dropped with a warning; those of out-of-service generators are noted."""
    keys, load_keys = _unit_keys(case)
    every_generator = {(int(case.buses.number[b]), str(g).strip().upper())
                       for b, g in zip(case.generators.bus, case.generators.gen_id)}
    out: dict[str, list[DyrRecord]] = {"machine": [], "exciter": [], "governor": [],
                                       "stabilizer": [], "load": []}
    unsupported: dict[str, list[DyrRecord]] = {}
    orphans: dict[str, list[DyrRecord]] = {"generator": [], "load": []}
    for r in dyr.records:
        kind = "load" if r.record_type == "USRLOD" else _kind(r.model)
        if r.model not in SUPPORTED:
            unsupported.setdefault(r.model, []).append(r)
        elif kind == "load" and _key(r) not in load_keys:
            orphans["load"].append(r)
        elif kind != "load" and _key(r) not in every_generator:
            orphans["generator"].append(r)
        elif kind != "load" and _key(r) not in keys:
            notes.append(f"{device_label(r)}: its generator is out of service; ignored")
        else:
            out[kind].append(r)
    messages = []
    for what, rs in orphans.items():
        if rs:
            listing = "; ".join(device_label(r) + (
                f": no in-service load record (bus {r.bus}, LID '{r.device_id}')"
                if what == "load" else "") for r in rs[:10]) + (
                f"; and {len(rs) - 10} more" if len(rs) > 10 else "")
            messages.append(f"{len(rs)} dynamic record(s) name a {what} (bus, ID) that the "
                            f"case {case.source} does not have"
                            f"{' in service' if what == 'load' else ''}: {listing}")
    if messages and strict:
        raise ModelError("; ".join(messages) + " (CompileOptions(strict=False) drops them)")
    for message in messages:
        warnings.warn(message + "; dropped", ModelWarning, stacklevel=3)
        notes.append(message + "; dropped")
    if unsupported:
        listing = "; ".join(
            f"{m} x{len(rs)} (first at line {rs[0].line}): " + _FALLBACK.get(
                "load" if rs[0].record_type == "USRLOD" else _kind(m), "dropped")
            for m, rs in unsupported.items())
        message = f"{dyr.source}: unsupported dynamic models: {listing}"
        if strict:
            raise DyrError(message.replace(": dropped", "") + " (CompileOptions(strict=False) "
                           "drops them with the fallbacks listed)")
        warnings.warn(message, ModelWarning, stacklevel=3)
        notes.append(message)
    return {kind: _without_repeats(rs, kind, notes) for kind, rs in out.items()}


def _sentinel_notes(records: dict[str, list[DyrRecord]]) -> list[str]:
    """The build notes of CON values read as WECC/PSS/E sentinels (`Con.sentinel_meaning`),
    model by model."""
    every = [r for rs in records.values() for r in rs]
    models = {**MACHINES, **EXCITERS, **GOVERNORS, **STABILIZERS, **LOAD_MODELS,
              **COMPOSITE_LOADS}
    return [note for name, model in models.items()
            for note in model.sentinel_notes([r for r in every if r.model == name])]


def _without_repeats(records: list[DyrRecord], kind: str, notes: list[str]) -> list[DyrRecord]:
    """`records` with identical repeats of a unit's record read once (noted); ModelError
    naming both lines where one unit has two different records of `kind`."""
    first: dict[tuple, DyrRecord] = {}
    kept = []
    for r in records:
        seen = first.setdefault(_key(r), r)
        if seen is r:
            kept.append(r)
        elif (seen.model, seen.cons, seen.icons) == (r.model, r.cons, r.icons):
            notes.append(f"{r.source}:{r.line}: {device_label(r)} repeats line {seen.line} "
                         "exactly: read once")
        else:
            raise ModelError(f"{r.source}:{r.line}: bus {r.bus} id '{r.device_id}' has a "
                             f"second {kind} model ({r.model}; the first, {seen.model}, is at "
                             f"line {seen.line})" if seen.model != r.model else
                             f"{r.source}:{r.line}: {device_label(r)} repeats line {seen.line} "
                             "with other values")
    return kept


def _report_model_notes(case: Case, groups, notes: list[str]) -> None:
    """Every device group's `notes` (approximations, dropped data), whatever its family,
    into the compile report, with one ModelWarning naming them."""
    remarks = [line for g in groups for line in g.model.notes(g.params, g.labels)]
    if remarks:
        warnings.warn(f"{case.source}: {len(remarks)} model note(s): " + "; ".join(remarks[:10])
                      + ("; ..." if len(remarks) > 10 else ""), ModelWarning, stacklevel=3)
        notes.extend(remarks)


FLOAT32_MAX = float(np.finfo(np.float32).max)


def _check_values(model: GridModel, precision: str) -> None:
    """ModelError naming the device and parameter (or the model field) of a value that is
    not finite, or that the cast to precision "float32" would turn into inf."""
    limit = FLOAT32_MAX if precision == "float32" else math.inf
    allowed = "finite" + (f" with |x| <= {limit:.3g} (precision = 'float32'; "
                          "'float64' takes larger values)" if precision == "float32" else "")

    def first_bad(values) -> int | None:
        a = np.asarray(values)
        if not np.issubdtype(a.dtype, np.inexact):
            return None
        flagged = np.flatnonzero(~np.isfinite(a) | (np.abs(a) > limit))
        return int(flagged[0]) if flagged.size else None

    for family in FAMILIES:
        for g in getattr(model, family):
            for name, values in g.params.items():
                k = first_bad(values)
                if k is not None:
                    one_per_unit = np.ndim(values) == 1 and k < len(g.labels)
                    label = g.labels[k] if one_per_unit else g.model.name
                    raise ModelError(f"{label}: {name.upper()} = "
                                     f"{np.ravel(values)[k]:g}: must be {allowed}")
    for path, values in jax.tree_util.tree_leaves_with_path(model):
        k = first_bad(values)
        if k is not None:
            raise ModelError(f"compiled model{jax.tree_util.keystr(path)} = "
                             f"{np.ravel(values)[k]}: must be {allowed}")


def _labels(case: Case, name: str, units) -> tuple[str, ...]:
    gen = case.generators
    return tuple(f"{name} at bus {case.buses.number[gen.bus[u]]} id '{gen.gen_id[u].strip()}'"
                 for u in units)


class Pending(NamedTuple):
    """One group of units to start: its model, CON params (prepared), labels, the units
    (generator or load-record indices in the case) and `index`, what `init_ports` picks
    them by (machine positions; load-record indices)."""

    model: type
    params: dict
    labels: tuple[str, ...]
    units: tuple[int, ...]
    index: tuple[int, ...]


def machine_bases(case: Case, pf: PowerFlowResult, machines: list[Pending], order: np.ndarray,
                  rule: str, notes: list[str]) -> np.ndarray:
    """MBASE (MVA) of each machine in `order` (0 in the RAW: the system base).

    [choice] rule "raw": as written (the PSS/E reading). "gridpack" (default): a GENSAL or
    GENROU that the power flow loads beyond its MBASE gets MBASE = 1.2·|S|, as GridPACK, the
    simulator of the PARS study, does when it reads these models; its per-unit data (X''d,
    H, the governor's limits) then act on that base. Each change is noted.
    """
    gen = case.generators
    mbase = np.where(gen.mbase[order] > 0, gen.mbase[order], case.base_mva)
    if rule == "raw":
        return mbase
    loading = np.abs(pf.pg[order] + 1j * pf.qg[order]) * case.base_mva
    names = [g.model.name for g in machines for _ in g.units]
    labels = [label for g in machines for label in g.labels]
    raised = np.isin(names, GRIDPACK_RESIZED) & (loading > mbase)
    for k in np.flatnonzero(raised):
        notes.append(f"{labels[k]}: loaded {loading[k]:.1f} MVA by the power flow, beyond MBASE = "
                     f"{mbase[k]:g} MVA: MBASE taken as {MBASE_MARGIN:g} × {loading[k]:.1f} MVA "
                     "(GridPACK's rule; CompileOptions(machine_base='raw') keeps the RAW's)")
    return np.where(raised, MBASE_MARGIN * loading, mbase)


def _machine_groups(case, records, keys, strict, notes, described) -> list[Pending]:
    """Machine groups in MACHINES order, CON params with ra, xs, zx; index = position in
    that order.

    An in-service generator without a machine model becomes a constant-admittance negative
    load (`_unmodelled_admittance`), noted. Strict mode allows it only where the DYR data
    have no record of it at all (`described`: (bus, ID) of every record read), as
    ACTIVSg2000's files leave their 98 renewable units; one with other records (an
    exciter, a governor) but no machine model is a ModelError."""
    gen = case.generators
    missing = sorted(set(keys.values()) - {keys[_key(r)] for r in records})
    if missing:
        def listing(units):
            return ", ".join(f"bus {case.buses.number[gen.bus[u]]} id "
                             f"'{gen.gen_id[u].strip()}'" for u in units[:10]) + (
                                 f", and {len(units) - 10} more" if len(units) > 10 else "")

        unit_key = {u: k for k, u in keys.items()}
        partial = [u for u in missing if unit_key[u] in described]
        if strict and partial:
            raise ModelError(f"{case.source}: {len(partial)} in-service generator(s) with "
                             f"dynamic records but no machine model: {listing(partial)}")
        mw = float(np.sum(gen.pg[missing])) * case.base_mva
        notes.append(f"{len(missing)} in-service generator(s), {mw:.1f} MW, without a machine "
                     f"model: {listing(missing)}; " + _FALLBACK["machine"])
    groups = []
    for name, model in MACHINES.items():
        rs = [r for r in records if r.model == name]
        if not rs:
            continue
        units = tuple(keys[_key(r)] for r in rs)
        p = model.read(rs)
        p.update(ra=gen.zr[list(units)], zx=gen.zx[list(units)])
        p["xs"] = np.asarray(model.source_reactance(p), dtype=float)
        for r, zx, xs in zip(rs, p["zx"], p["xs"]):
            if abs(zx - xs) > 1e-3:
                notes.append(f"{r.source}:{r.line}: {name} at bus {r.bus}: ZSOURCE X = {zx:g} "
                             f"differs from the model's {xs:g}; the model's value is used")
        first = sum(len(g.units) for g in groups)
        groups.append(Pending(model, model.prepare(p), _labels(case, name, units), units,
                              tuple(range(first, first + len(units)))))
    if not groups:
        raise ModelError(f"{case.source}: no machine has a supported dynamic model")
    return groups


def _controller_groups(case, records, registry, keys, position) -> list[Pending]:
    """Exciter or governor groups attached to modelled machines; index = their machines'
    positions."""
    groups = []
    for name, model in registry.items():
        rs = [r for r in records if r.model == name and keys[_key(r)] in position]
        if rs:
            units = tuple(keys[_key(r)] for r in rs)
            groups.append(Pending(model, model.prepare(model.read(rs)),
                                  _labels(case, name, units), units,
                                  tuple(position[u] for u in units)))
    return groups


def _load_groups(records, load_keys, composite: CompositeOptions) -> list[Pending]:
    """Load-model groups in LOAD_MODELS order, then one group of every composite load
    (`composite_records` order) run by `run_model(composite)`; index = their load records."""
    groups = []
    for name, model in LOAD_MODELS.items():
        rs = [r for r in records if r.model == name]
        if rs:
            groups.append(_load_group(model, model.prepare(model.read(rs)), rs, load_keys))
    rs = composite_records(records)
    if rs:
        model = run_model(composite)
        groups.append(_load_group(model, model.prepare(read_records(rs)), rs, load_keys))
    return groups


def _load_group(model, params, records, load_keys) -> Pending:
    """The group of `records`' units; index = their load records."""
    units = tuple(load_keys[_key(r)] for r in records)
    return Pending(model, params, tuple(device_label(r) for r in records), units, units)


def _without_composite(case: Case, groups: list[Pending]) -> Case:
    """`case` with the load records of composite loads out of service: `expand` moves them
    to the load buses it adds, so the other load models' sites see the expanded case's bus
    load."""
    taken = [u for g in groups if g.model.name in COMPOSITE_LOADS for u in g.units]
    in_service = case.loads.in_service.copy()
    in_service[taken] = False
    return dataclasses.replace(case, loads=dataclasses.replace(case.loads,
                                                               in_service=in_service))


def _start_point(case, pf, vt0, i0, bus_p, mbase, options) -> StartPoint:
    """The power-flow point: machine terminal voltages vt0 and currents i0 (n_gen,) complex
    (MBASE), every load record's site; bus_p (n_bus,) the load drawn at each bus, p.u.;
    mbase (n_gen,) the machines' MBASE, MVA."""
    loads = case.loads
    vm = pf.vm[loads.bus]
    record_s = (loads.p_power + 1j * loads.q_power
                + (loads.p_current + 1j * loads.q_current) * vm
                + (loads.p_impedance + 1j * loads.q_impedance) * vm ** 2)
    site = LoadSite(v0=vm * np.exp(1j * pf.va[loads.bus]), record_s=record_s,
                    bus_p=bus_p[loads.bus], sbase=case.base_mva, f_nom=case.frequency_hz,
                    motors=options.motors, composite=options.composite)
    with jax.enable_x64(True):
        zero = jnp.zeros(len(vt0))
        signals = Signals(vt=jnp.asarray(vt0), current=jnp.asarray(i0),
                          i_dq=jnp.zeros(len(vt0), complex), xadifd=zero, dw=zero, efd=zero,
                          pm=zero, vothsg=zero, v_load=jnp.zeros(0, complex),
                          omega_b=float(2 * np.pi * case.frequency_hz))
    return StartPoint(signals=signals, site=site, mbase=np.asarray(mbase, dtype=float))


def _start(pending: dict[str, list[Pending]],
           point: StartPoint) -> tuple[dict[str, list[tuple[Pending, Initial]]], StartPoint]:
    """Every family's groups initialised (float64) in FAMILIES order, machines -> exciters
    -> governors -> loads -> stabilizers (spec §0): each group reads its init ports from the
    point, and the `Signals` fields in its output (the machines' EFD0, Pm0, XadIfd0) are
    written back for the families after it. Returns {family: [(group, Initial)]} and the final point."""
    started = {}
    with jax.enable_x64(True):
        for family in FAMILIES:
            started[family] = []
            for g in pending[family]:
                k = np.asarray(g.index, dtype=int)
                start = g.model.init(_jnp(g.params), g.model.init_ports(point, k, g.labels))
                signals = {name: getattr(point.signals, name).at[k].set(value)
                           for name, value in start.output.items() if name in Signals._fields}
                point = point._replace(signals=point.signals._replace(**signals))
                started[family].append((g, start))
    return started, point


def _expand(case, pf, records, started, composite: CompositeOptions, notes):
    """The composite loads' buses and branches added to the case after they started
    (`expand`, its notes appended). Returns (case, pf: its power flow, started: the load
    groups with the composite group's units now the load records `expand` moved to the load
    buses, names: {internal bus number: name}, upstream: the system buses that get load slots
    too (feeder shedding), bus indices); case and pf unchanged without composite loads."""
    for k, (g, start) in enumerate(started):
        if g.model.name in COMPOSITE_LOADS:
            grown = expand(case, pf.vm, pf.va, composite_records(records), g.units, start, notes)
            pf = dataclasses.replace(pf, case=grown.case, vm=grown.vm, va=grown.va,
                                     bus_kind=np.concatenate([pf.bus_kind, np.full(
                                         len(grown.vm) - len(pf.vm), PQ)]))
            moved = (g._replace(units=tuple(grown.units.tolist())), start)
            upstream = grown.system_bus if composite.shedding == "feeder" else np.zeros(0, int)
            return grown.case, pf, started[:k] + [moved] + started[k + 1:], grown.names, upstream
    return case, pf, started, {}, np.zeros(0, dtype=int)


def _note_idle_stabilizers(pending: dict[str, list[Pending]], notes: list[str]) -> None:
    """A note for every stabilizer whose machine has no exciter to take its output."""
    excited = {u for g in pending["exciters"] for u in g.units}
    for g in pending["stabilizers"]:
        notes.extend(f"{label}: its machine has no modelled exciter; the stabilizer's output "
                     "drives nothing" for u, label in zip(g.units, g.labels) if u not in excited)


def _device_groups(started) -> tuple[tuple[DeviceGroup, ...], tuple[dict, ...]]:
    """(groups, initial states) of started machines, exciters, governors or stabilizers."""
    return (tuple(DeviceGroup(params=_np(s.params), model=g.model, index=g.index,
                              labels=g.labels) for g, s in started),
            tuple(_np(s.states) for _, s in started))


# --------------------------------------------------------------------------- #
# Loads and unmodelled generators
# --------------------------------------------------------------------------- #

def _bus_load_at(case: Case, pf: PowerFlowResult) -> np.ndarray:
    """(n_bus,) complex load drawn at the power-flow voltages (the case's own ZIP data)."""
    s_power, s_current, s_impedance = bus_loads(case)
    return s_power + s_current * pf.vm + s_impedance * pf.vm ** 2


def _unmodelled_admittance(case, pf, on, order, notes) -> np.ndarray:
    """(n_bus,) admittance of generators without a machine model, as negative loads."""
    gen = case.generators
    rest = np.setdiff1d(np.flatnonzero(on), order)
    s = np.zeros(case.n_bus, dtype=complex)
    np.add.at(s, gen.bus[rest], pf.pg[rest] + 1j * pf.qg[rest])
    return -np.conj(s) / np.maximum(pf.vm, 1e-6) ** 2


class LoadModelUnits(NamedTuple):
    """The units of one dynamic load model, initialised at the power flow (n_unit each)."""

    model: type
    labels: tuple[str, ...]
    buses: np.ndarray  # bus indices
    params: dict
    states: dict
    flags: dict
    s0: np.ndarray  # complex power each unit draws at the power flow, p.u. system base


def _load_units(case, started, bus_p, notes) -> list[LoadModelUnits]:
    """The started load-model groups as units at their buses, their load report in notes;
    bus_p (n_bus,) is the load drawn at the power flow, p.u. system base."""
    groups = []
    for g, start in started:
        notes.extend(f"load report: {line}" for line in start.report)
        groups.append(LoadModelUnits(g.model, g.labels, case.loads.bus[list(g.units)],
                                     _np(start.params), _np(start.states), _np(start.flags),
                                     np.asarray(start.output["s0"])))
    drawn = np.zeros(case.n_bus)
    for g in groups:
        np.add.at(drawn, g.buses, g.s0.real)
    for b in np.flatnonzero(drawn > bus_p + 1e-9):
        notes.append(f"load report: bus {case.buses.number[b]}: load models draw "
                     f"{drawn[b] * case.base_mva:.2f} MW of a {bus_p[b] * case.base_mva:.2f} MW "
                     "load; the remainder is a negative load")
    return groups


def _load_buses(case: Case, s_load: np.ndarray, options: CompileOptions,
                model_buses) -> np.ndarray:
    """Bus indices that get a load slot (always those with a load model)."""
    has_load = np.flatnonzero(np.abs(s_load) > 0)
    if options.load_buses is None:
        return np.union1d(has_load, np.asarray(model_buses, dtype=int)).astype(int)
    chosen = case.bus_index(list(options.load_buses)) if options.load_buses else np.zeros(0, int)
    no_load = [case.buses.number[b] for b in chosen if b not in set(has_load)]
    if no_load:
        raise ValueError(f"CompileOptions.load_buses: buses {no_load} carry no load")
    if options.loads.has_injections:
        chosen = has_load  # every ZIP load with I or P parts needs a slot
    return np.asarray(sorted(set(chosen.tolist()) | set(int(b) for b in model_buses)), dtype=int)


# --------------------------------------------------------------------------- #
# Checks and conversions
# --------------------------------------------------------------------------- #

def _check_initial_state(model: GridModel, tolerance: float, notes: list[str]) -> None:
    """Warn (and note) every device variable that is not at rest or starts outside a limit.

    Load models' flags must also stay put over one 1 ms step at the power-flow voltages.
    """
    with jax.enable_x64(True):
        rates, violations, stepped = jax.device_get(_rest_check(model))
    x0 = model.initial
    problems = []
    for family, drift, bad_by_group, states in zip(FAMILIES, rates, violations,
                                                   x0.integrated()):
        for g, dx, bad_by_name, x in zip(getattr(model, family), drift, bad_by_group, states):
            for name, rate in dx.items():
                rate = np.abs(rate)
                for u in np.flatnonzero(rate > tolerance):
                    problems.append(f"{g.labels[u]}: d{name}/dt = {rate[u]:.3g} at t = 0")
            for name, bad in bad_by_name.items():
                for u in np.flatnonzero(bad):
                    value = f" = {float(x[name][u]):.4g}" if name in x else ""
                    problems.append(f"{g.labels[u]}: initial {name}{value} is outside its limits")
    for g, before, after in zip(model.loads, x0.load_flags, stepped):
        for name in set(before) - set(g.model.relaxing):
            change = np.abs(after[name] - np.asarray(before[name]))
            for u in np.flatnonzero(change > tolerance):
                problems.append(f"{g.labels[u]}: {name} moves by {change[u]:.3g} in the "
                                "first 1 ms")
    if problems:
        message = (f"{len(problems)} device variable(s) not at rest at t = 0: "
                   + "; ".join(problems[:20]) + ("; ..." if len(problems) > 20 else ""))
        warnings.warn(message, InitWarning, stacklevel=3)
        notes.extend(problems)


@jax.jit
def _rest_check(model: GridModel):
    """`_check_initial_state`'s numbers, one compiled program (evaluated eagerly, its
    operations were each compiled on their own: about a hundred small XLA compiles per
    model): the devices' rates at the initial state (per family, group: {state: (n,)}), their
    initial values outside limits (per family, group: {state: (n,) bool}) and the load
    models' flags after one 1-ms step at the power-flow voltages (per load group)."""
    x0 = model.initial
    fault = network.fault_view(model.network, 0, 1.0)
    rates, v, _ = derivatives(model, x0, fault, 0.0, INIT_SWEEPS)
    violations = [[g.model.init_violations(g.params, x)
                   for g, x in zip(getattr(model, family), states)]
                  for family, states in zip(FAMILIES, x0.integrated())]
    stepped = update_loads(model, x0.replace(v=v), x0.v, 1e-3)
    return rates, violations, stepped.load_flags


def _jnp(params: dict) -> dict:
    return {k: jnp.asarray(v) for k, v in params.items()}


def _np(tree: dict) -> dict:
    return {k: np.asarray(v) for k, v in tree.items()}
