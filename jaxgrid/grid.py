"""The compiled grid: static structure (Python ints and tuples) plus parameter and state arrays.

Built by `jaxgrid.compile.compile_model`; read by `jaxgrid.dynamics` and `jaxgrid.simulate`
(how it is integrated is not the model's: `jaxgrid.steppers.Solver`).
Array leaves are NumPy arrays already in the model's precision (float32/complex64 by
default, float64/complex128 with `precision="float64"`), so `jit` takes them as they are.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from flax import struct

from jaxgrid.busnames import resolve_bus
from jaxgrid.network import Network


@struct.dataclass
class DeviceGroup:
    """All units of one dynamic model.

    Attributes:
      params: {name: (n_unit,)} CONs (lower-case PSS/E names), derived constants, references.
      model: the model class (static).
      index: (n_unit,) static index of each unit's machine in the model's machine order
        (machines, exciters, governors, stabilizers) or of its load slot (load models).
      labels: static "MODEL at bus B id 'I'" per unit, for messages.
    """

    params: dict
    model: type = struct.field(pytree_node=False)
    index: tuple[int, ...] = struct.field(pytree_node=False)
    labels: tuple[str, ...] = struct.field(pytree_node=False)


class Integrated(NamedTuple):
    """The states Heun integrates, per family a tuple over its device groups of {state name:
    (n_unit,)} (p.u., rad); also their rates (`jaxgrid.dynamics.derivatives`).

    Attributes:
      machines, exciters, governors, loads, stabilizers: as `GridState`'s fields of those
        names (`jaxgrid.dynamics.FAMILIES` order).
    """

    machines: tuple
    exciters: tuple
    governors: tuple
    loads: tuple
    stabilizers: tuple


@struct.dataclass
class GridState:
    """The dynamic state of one rollout.

    Attributes:
      machines, exciters, governors, loads, stabilizers: per device group, {state name:
        (n_unit,)} continuous states (p.u., rad), integrated by Heun.
      load_flags: per load group, {flag: (n_unit,)} states changed once per step (timers,
        run/stall flags, latches, measured voltage and frequency).
      load_left: (n_load,) fraction of each load slot's initial load still connected
        (load shedding; every load type at the slot is scaled by it).
      v: (n_slot,) complex slot voltages of the last network solution (warm start), p.u.
    """

    machines: tuple[dict, ...]
    exciters: tuple[dict, ...]
    governors: tuple[dict, ...]
    loads: tuple[dict, ...]
    load_flags: tuple[dict, ...]
    load_left: np.ndarray
    v: np.ndarray
    stabilizers: tuple[dict, ...] = ()

    def integrated(self) -> Integrated:
        """The Heun-integrated part."""
        return Integrated(self.machines, self.exciters, self.governors, self.loads,
                          self.stabilizers)

    def with_integrated(self, states: Integrated, v) -> GridState:
        """This state with new integrated parts `states` and slot voltages v."""
        return self.replace(**states._asdict(), v=v)


@struct.dataclass
class GridModel:
    """A case compiled for simulation.

    Machines are ordered group by group (`gen_bus`, `gen_id` give each one's RAW identity).
    Slots: the first n_gen are the machines' buses, then one per entry of `load_bus`.

    Attributes:
      machines, exciters, governors, stabilizers: tuples of DeviceGroup.
      loads: DeviceGroup per dynamic load model (motors), units indexed by load slot.
      network: impedance views (jaxgrid.network.Network).
      z_source: (n_gen,) complex Norton impedance ra + j·xs, p.u. MBASE.
      y_norton: (n_gen,) complex Norton admittance, p.u. system base.
      mbase_ratio: (n_gen,) MBASE / system base.
      efd0, pm0: (n_gen,) field voltage and mechanical power held by machines without an
        exciter or governor, p.u. MBASE.
      load_y, load_s_i, load_s_p: (n_load,) complex ZIP parts at the load slots (p.u.).
      load_vm0: (n_load,) power-flow voltage magnitude at the load slots, p.u.
      load_p0: (n_load,) initial active power of all loads at each load slot (static and
        motors), p.u. system base: what shedding a fraction of the slot removes.
      v0: (n_bus,) complex power-flow bus voltages, p.u.
      initial: GridState at the power-flow point.
      bus_numbers: RAW bus numbers (n_bus,), static.  gen_bus, gen_id: static per machine.
      slot_bus: static bus index per slot; load_bus: static bus index per load slot.
      omega_b: base angular frequency 2π·f, rad/s (static).
      pq_break: p.u. voltage where constant power turns into constant admittance (static).
      precision: "float32" or "float64" (static).
      notes: static tuple of strings: what the compiler changed, dropped or warned about.
      bus_names: static name per bus (n_bus,): "Bus<N>" for RAW bus N, and for the internal
        buses of a composite load at bus N "Bus<N>_lowBus" / "Bus<N>_loadBus" (the PNNL
        task files' names; numbering in `jaxgrid.models.cmld`). Empty: all "Bus<N>".
    """

    machines: tuple[DeviceGroup, ...]
    exciters: tuple[DeviceGroup, ...]
    governors: tuple[DeviceGroup, ...]
    loads: tuple[DeviceGroup, ...]
    network: Network
    z_source: np.ndarray
    y_norton: np.ndarray
    mbase_ratio: np.ndarray
    efd0: np.ndarray
    pm0: np.ndarray
    load_y: np.ndarray
    load_s_i: np.ndarray
    load_s_p: np.ndarray
    load_vm0: np.ndarray
    load_p0: np.ndarray
    v0: np.ndarray
    initial: GridState
    bus_numbers: tuple[int, ...] = struct.field(pytree_node=False)
    gen_bus: tuple[int, ...] = struct.field(pytree_node=False)
    gen_id: tuple[str, ...] = struct.field(pytree_node=False)
    slot_bus: tuple[int, ...] = struct.field(pytree_node=False)
    load_bus: tuple[int, ...] = struct.field(pytree_node=False)
    omega_b: float = struct.field(pytree_node=False)
    pq_break: float = struct.field(pytree_node=False)
    precision: str = struct.field(pytree_node=False)
    notes: tuple[str, ...] = struct.field(pytree_node=False)
    bus_names: tuple[str, ...] = struct.field(pytree_node=False, default=())
    stabilizers: tuple[DeviceGroup, ...] = ()

    @property
    def n_bus(self) -> int:
        return len(self.bus_numbers)

    @property
    def n_gen(self) -> int:
        return len(self.gen_bus)

    def load_slot(self, bus_number: int) -> int:
        """Index of a bus (RAW number) among the load slots; ValueError if it has none."""
        index = self.bus_numbers.index(bus_number) if bus_number in self.bus_numbers else -1
        if index not in self.load_bus:
            raise ValueError(f"bus {bus_number} has no controllable load slot "
                             f"(buses with one: {[self.bus_numbers[b] for b in self.load_bus]})")
        return self.load_bus.index(index)

    def bus_number_by_name(self, name: str) -> int:
        """Bus number of a name (case-insensitive): an entry of `bus_names` such as
        "Bus20_loadBus", or "Bus<N>" for any bus number N of the model
        (`jaxgrid.busnames.resolve_bus`); ValueError if none."""
        names = {bus_name.lower(): number
                 for bus_name, number in zip(self.bus_names, self.bus_numbers)}
        return resolve_bus(name, names, self.bus_numbers, "the model")

    def bus_index_by_name(self, name: str) -> int:
        """Index (into bus_numbers, trajectories' bus axis) of a bus name; see
        `bus_number_by_name`."""
        return self.bus_index(self.bus_number_by_name(name))

    def bus_index(self, bus_number: int) -> int:
        """Index of a RAW bus number; ValueError naming the bus if unknown."""
        if bus_number not in self.bus_numbers:
            raise ValueError(f"bus {bus_number} is not in the case")
        return self.bus_numbers.index(bus_number)
