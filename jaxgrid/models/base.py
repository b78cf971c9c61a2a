"""What every dynamic device model shares: its CON table, validation, ports and limiter blocks.

A model is a class with class-level structure (PSS/E name, CON order with units and
allowed ranges, state names) and pure functions over parameter and state dicts whose
arrays have one row per unit, so one family's equations are one vectorised expression
whatever the number of units. Limiter conventions follow IEEE 421.5 as summarised in
`shared/specs/machines-exciters-governors.md` §0.

Every family declares its ports once, as PowerSimulationsDynamics.jl does
(`src/base/ports.jl`): `ports(signals, k, flags)` picks what its units read from the
model-wide `Signals` of one evaluation, `rates(p, x, ports) -> (output, dx)` gives the
state derivatives and the signal it drives (`output` names the `Signals` field: EFD for
exciters, Pm for governors, VOTHSG for stabilizers; None for machines and loads). `jaxgrid.dynamics.derivatives`
runs the families in causal order, each reading the signals the earlier ones wrote.
Initialisation mirrors it: `init_ports(point, k, labels)` picks what the units start from
out of the model-wide `StartPoint` (the power flow), `init(p, ports) -> Initial` gives
their parameters, states and what they hand on; `jaxgrid.compile` runs the families in
the order machines -> exciters -> governors -> loads -> stabilizers (spec §0; a stabilizer's
output is zero at rest, so the exciters' references do not depend on it).
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrid.records import DyrRecord
from jaxgrid.models.options import CompositeOptions, MotorOptions


INF = math.inf
LIMIT_TOL = 1e-6  # p.u.: initial values computed in float64 sit on a limit to round-off
TIMER_TOL_STEPS = 0.01  # of a step: see timer_fires

Array = jnp.ndarray
Params = dict[str, Array]
States = dict[str, Array]


class ModelError(ValueError):
    """Dynamic data that a model cannot use (names the file, line, device and field)."""


SENTINELS = (999.0, 9999.0)  # the values WECC and PSS/E data use to switch a function off


@dataclasses.dataclass(frozen=True)
class Sentinel:
    """How a CON reads the WECC/PSS/E values that switch its function off: 999 and 9999
    (their negatives where the CON is a lower limit), where the model's comparison makes such
    a value mean `meaning` (e.g. a reclose voltage of 999 p.u. is never exceeded: "never
    recloses"). The table of every declaration is in docs/models.md ("Sentinel values")."""

    meaning: str
    lower: bool = False

    @property
    def values(self) -> tuple[float, ...]:
        return tuple(-v if self.lower else v for v in SENTINELS)


@dataclasses.dataclass(frozen=True)
class Con:
    """One PSS/E CON: lower-case name, unit, meaning and allowed closed range [lo, hi].

    `positive` excludes the lower bound 0 itself (time constants that divide). `sentinel`:
    the WECC/PSS/E "off" values the CON also accepts, outside [lo, hi] too (`Sentinel`).
    """

    name: str
    unit: str
    info: str
    lo: float = -INF
    hi: float = INF
    positive: bool = False
    sentinel: Sentinel | None = None

    def check(self, value: float) -> str | None:
        """A reason why `value` is not allowed, or None."""
        if not math.isfinite(value):
            return "must be finite"
        if self.sentinel is not None and value in self.sentinel.values:
            return None
        if self.positive and value <= 0:
            return "must be > 0"
        if not self.lo <= value <= self.hi:
            return f"must lie in [{self.lo}, {self.hi}]"
        return None

    def admits(self, values: Array) -> Array:
        """`check` on an array, jnp (run time: `jaxgrid.simulate.parameters_valid`): True
        where the value is allowed (finiteness is checked separately)."""
        ok = (values >= self.lo) & (values <= self.hi) & ((values > 0) | (not self.positive))
        if self.sentinel is None:
            return ok
        return ok | jnp.isin(values, jnp.asarray(self.sentinel.values, values.dtype))

    def sentinel_meaning(self, value: float) -> str | None:
        """What `value` means when only its reading as a sentinel admits it (outside
        [lo, hi]), else None (an ordinary value: a time of 9999 s within the range is
        simply never reached)."""
        if self.sentinel is None or value not in self.sentinel.values:
            return None
        return None if self.lo <= value <= self.hi else self.sentinel.meaning


def device_label(record: DyrRecord) -> str:
    """'file:line: MODEL at bus B id I' for messages."""
    return f"{record.source}:{record.line}: {record.model} at bus {record.bus} id '{record.device_id}'"


class Signals(NamedTuple):
    """The interface signals of one evaluation of the grid, model-wide.

    Attributes:
      vt: (n_gen,) machine terminal voltages, network frame, complex p.u.
      current: (n_gen,) machine currents injected into the bus, network frame, complex
        p.u. on MBASE.
      i_dq: (n_gen,) the same currents in each machine's rotor frame, id + j·iq.
      xadifd: (n_gen,) field currents XadIfd, p.u.
      dw: (n_gen,) speed deviations, p.u.
      efd: (n_gen,) field voltages, p.u. (EFD0 where no exciter drives them).
      pm: (n_gen,) mechanical powers, p.u. MBASE (Pm0 where no governor drives them).
      vothsg: (n_gen,) stabilizer outputs VOTHSG, p.u., the exciters' VS input (0 where no
        stabilizer drives them).
      v_load: (n_load,) load-slot voltages, network frame, complex p.u.
      omega_b: base angular frequency, rad/s (Python float).
    """

    vt: Array
    current: Array
    i_dq: Array
    xadifd: Array
    dw: Array
    efd: Array
    pm: Array
    vothsg: Array
    v_load: Array
    omega_b: float

    @property
    def pe(self) -> Array:
        """(n_gen,) electrical power at the machine terminals, Re(Vt·conj(I)), p.u. MBASE."""
        return jnp.real(self.vt * jnp.conj(self.current))


class LoadSite(NamedTuple):
    """Where load models sit, from the power flow (NumPy, float64, arrays (n_unit,)), and
    the readings of their data.

    Attributes:
      v0: complex bus voltage, p.u.
      record_s: complex power of the unit's RAW load record at |v0|, p.u. system base.
      bus_p: active power of all loads at the bus at |v0|, p.u. system base.
      sbase: system base, MVA.  f_nom: nominal frequency, Hz.
      labels: "MODEL at bus B id 'I'" per unit, for the load report (optional).
      motors: readings of motor-load data (ACMTBLU1, CIM5BL/CIM6BL, composite loads).
      composite: readings of composite-load data (CMLDBLU1/2).
    """

    v0: np.ndarray
    record_s: np.ndarray
    bus_p: np.ndarray
    sbase: float
    f_nom: float
    labels: tuple[str, ...] = ()
    motors: MotorOptions | None = None
    composite: CompositeOptions | None = None

    @property
    def record_p(self) -> np.ndarray:
        """Active power of the unit's RAW load record at |v0|, p.u. system base."""
        return np.real(self.record_s)

    def label(self, k: int) -> str:
        """How the load report names unit k."""
        return self.labels[k] if self.labels else f"unit {k}"

    def pick(self, k, labels: tuple[str, ...]) -> LoadSite:
        """The site of units k (indices into this site's units), named by labels."""
        return self._replace(v0=self.v0[k], record_s=self.record_s[k], bus_p=self.bus_p[k],
                             labels=labels)


class StartPoint(NamedTuple):
    """The power-flow point every device starts from, model-wide (float64): a family's
    `init_ports` picks its units' init ports from it, as `ports` picks from `Signals`.

    Attributes:
      signals: `Signals` at t = 0: the machines' terminal voltages and currents of the
        power flow and dw = 0; efd, pm and xadifd as the machines' `init` set them (0
        before); i_dq 0 (unused); v_load empty (load slots are chosen after the load
        models start).
      site: `LoadSite` of every load record of the case (n_record,), without labels.
      mbase: (n_gen,) the machines' MBASE, MVA (governors with a turbine rating of their
        own, GGOV1's Trate, convert to it).
    """

    signals: Signals
    site: LoadSite
    mbase: np.ndarray


class Initial(NamedTuple):
    """What `DeviceModel.init` gives its units, arrays (n,).

    Attributes:
      params: p with what initialisation derives (set-points, Norton admittances, ...).
      states: {state: (n,)} at rest.
      output: what the units hand on: machines {efd, pm, xadifd} (`Signals` fields the
        later families start from), load models {s0: complex power drawn at the power flow,
        p.u. system base}; empty for exciters, governors and stabilizers.
      flags: {flag: (n,)} discrete states (load models; empty elsewhere).
      report: load-report lines naming the unit (load models; one per unit and per
        substituted CON value).
    """

    params: Params
    states: States
    output: dict[str, Array]
    flags: States = {}
    report: tuple[str, ...] = ()


def outside_limits(x: Array, lo: Array, hi: Array) -> Array:
    """True where x lies outside [lo − LIMIT_TOL, hi + LIMIT_TOL] (NaN counts as outside):
    the one rule for an initial value outside its limits."""
    return ~((x >= lo - LIMIT_TOL) & (x <= hi + LIMIT_TOL))


class DeviceModel:
    """Structure and contract shared by every device family.

    Subclasses set `name`, `cons` (PSS/E CON order), `states` and `n_icons` (integer
    values written before the CONs, e.g. IEEEG1's JBUS and M), of which the first
    `len(stored_icons)` are kept as parameters under those names. A family sets `output`
    (the `Signals` field its rates drive, or None) and implements `ports` and `rates`.
    """

    name: ClassVar[str]
    cons: ClassVar[tuple[Con, ...]]
    states: ClassVar[tuple[str, ...]]
    n_icons: ClassVar[int] = 0
    stored_icons: ClassVar[tuple[str, ...]] = ()
    output: ClassVar[str | None] = None

    @classmethod
    def ports(cls, signals: Signals, k: Array, flags: States) -> NamedTuple:
        """What the units at machine or load-slot indices k (n,) read from `signals`;
        flags: their discrete states (empty outside load models)."""
        raise NotImplementedError

    @classmethod
    def init_ports(cls, point: StartPoint, k: Array, labels: tuple[str, ...]) -> NamedTuple:
        """What the units at machine or load-record indices k (n,), named by labels, start
        from at the power-flow point."""
        raise NotImplementedError

    @classmethod
    def init(cls, p: Params, ports: NamedTuple) -> Initial:
        """Parameters, states at rest and what the units hand on, from their init ports."""
        raise NotImplementedError

    @classmethod
    def rates(cls, p: Params, x: States, ports: NamedTuple) -> tuple[Array | None, States]:
        """(output (n,) or None, {state: d/dt per second}) at the given ports."""
        raise NotImplementedError

    @classmethod
    def prepare(cls, p: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """CON arrays with the derived constants the model needs added (NumPy, compile
        time); none by default."""
        return p

    @classmethod
    def read(cls, records: Sequence[DyrRecord]) -> dict[str, np.ndarray]:
        """CON arrays (n_unit,) float64 from DYR records, range-checked, and the
        `stored_icons`."""
        n = len(cls.cons) + cls.n_icons
        values = np.zeros((len(records), len(cls.cons)))
        for k, rec in enumerate(records):
            if len(rec.cons) != n:
                raise ModelError(f"{device_label(rec)}: expected {n} values, found {len(rec.cons)}")
            icons = rec.cons[:cls.n_icons]
            cls.check_icons(rec, icons)
            for j, (con, value) in enumerate(zip(cls.cons, rec.cons[cls.n_icons:])):
                reason = con.check(value)
                if reason:
                    raise ModelError(f"{device_label(rec)}: CON({j + 1}) {con.name.upper()} "
                                     f"= {value:g} {con.unit}: {reason}")
                values[k, j] = value
        params = {con.name: values[:, j] for j, con in enumerate(cls.cons)}
        params |= {name: np.array([float(r.cons[j]) for r in records])
                   for j, name in enumerate(cls.stored_icons)}
        for k, rec in enumerate(records):
            reason = cls.check_combination({key: v[k] for key, v in params.items()})
            if reason:
                raise ModelError(f"{device_label(rec)}: {reason}")
        return params

    @classmethod
    def sentinel_notes(cls, records: Sequence[DyrRecord]) -> list[str]:
        """One build note per CON and value read as a sentinel (`Con.sentinel_meaning`),
        naming the first record and counting the others."""
        found: dict[tuple[int, float], list[DyrRecord]] = {}
        for rec in records:
            for j, (con, value) in enumerate(zip(cls.cons, rec.cons[cls.n_icons:])):
                if con.sentinel_meaning(value):
                    found.setdefault((j, value), []).append(rec)
        notes = []
        for (j, value), recs in found.items():
            con = cls.cons[j]
            more = f" (and {len(recs) - 1} more {cls.name} records)" if len(recs) > 1 else ""
            notes.append(f"{device_label(recs[0])}{more}: CON({j + 1}) {con.name.upper()} = "
                         f"{value:g} {con.unit} lies outside [{con.lo:g}, {con.hi:g}]: read as "
                         f"the WECC/PSS/E sentinel: {con.sentinel_meaning(value)}")
        return notes

    @classmethod
    def check_icons(cls, record: DyrRecord, icons: Sequence[float]) -> None:
        """Reject ICON values the model does not support (none by default)."""

    @classmethod
    def check_combination(cls, p: dict[str, float]) -> str | None:
        """A reason why one unit's CONs contradict each other, or None."""
        return None

    @classmethod
    def notes(cls, p: dict[str, np.ndarray], labels: Sequence[str] = ()) -> list[str]:
        """Warn-level remarks on the data (approximations, dropped values), one line per
        remark naming the unit by labels[k]; compile reports them (nothing by default)."""
        return []

    @classmethod
    def limits(cls, p: Params) -> dict[str, tuple[Array, Array]]:
        """Non-windup state limits {state: (lo, hi)}, applied after every update."""
        return {}

    @classmethod
    def init_violations(cls, p: Params, x: States) -> dict[str, Array]:
        """Per variable, (n,) bool of units whose initial value lies outside its limits
        (`outside_limits`)."""
        return {name: outside_limits(x[name], lo, hi)
                for name, (lo, hi) in cls.limits(p).items()}


# --------------------------------------------------------------------------- #
# Transfer-function blocks (jnp, elementwise over units)
# --------------------------------------------------------------------------- #

def safe(t: Array) -> Array:
    """A time constant usable as a divisor: 1 where t == 0 (the block is bypassed)."""
    return jnp.where(t > 0, t, 1.0)


def lag(x: Array, u: Array, t: Array) -> Array:
    """d/dt of a first-order lag state x with input u and time constant t (s); 0 if t == 0."""
    return jnp.where(t > 0, (u - x) / safe(t), 0.0)


def freeze_at_limits(dx: Array, x: Array, lo: Array, hi: Array) -> Array:
    """Non-windup rule: no derivative pushing a state already at a limit further out."""
    return jnp.where(((x >= hi) & (dx > 0)) | ((x <= lo) & (dx < 0)), 0.0, dx)


def lead_lag_output(x: Array, u: Array, t_lead: Array, t_lag: Array) -> Array:
    """Output of (1 + s t_lead)/(1 + s t_lag) whose lag state is x; u itself if t_lag == 0."""
    ratio = t_lead / safe(t_lag)
    return jnp.where(t_lag > 0, ratio * u + (1.0 - ratio) * x, u)


def timer_fires(elapsed: Array, setting: Array, dt: float) -> Array:
    """Whether a timer that accumulates dt (s) per step has reached its setting (s).

    It fires at elapsed >= setting − TIMER_TOL_STEPS·dt: the specs' "≥ T − 1e-9 s" (e.g.
    ACMTBLU1 §6.7) read with a tolerance that outlasts float32 round-off of the summed
    steps, so a float32 run fires on the same step as a float64 one.
    """
    return elapsed >= setting - TIMER_TOL_STEPS * dt


def surrogate_gradient(margin: Array, width: Array) -> Array:
    """Zero in value; the gradient of sigmoid(margin / width) (straight-through surrogate).

    Added as `switch_value + surrogate_gradient(m, w)·(on − off)` to a hard switch that is
    on where m > 0, it leaves the simulated trajectory bitwise unchanged and gives the switch
    the gradient of a sigmoid transition of width `width` (units of `margin`). width <= 0:
    no gradient (the exact model's zero). Used by the MPC's prediction model
    (`baselines.mpc.surrogate_model`).
    """
    on = width > 0
    soft = jax.nn.sigmoid(margin / jnp.where(on, width, 1.0))
    return jnp.where(on, soft - jax.lax.stop_gradient(soft), 0.0)


def quadratic_saturation(x: Array, a: Array, b: Array, xp=jnp) -> Array:
    """PSS/E quadratic saturation factor Se(x) = b (x − a)² / x for x > a, else 0
    (xp = numpy for host-side initialisation)."""
    xs = xp.where(x > a, x, a + 1.0)
    return xp.where(x > a, b * (xs - a) ** 2 / xp.maximum(xs, 1e-6), 0.0)


def quadratic_saturation_constants(x1, s1, x2, s2) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the quadratic curve through (x1, s1) and (x2, s2), arrays (n,).

    S1 = S2 = 0, or a zero point x1 or x2 (how DC-exciter data say "no saturation data",
    as ANDES also reads it), gives no saturation (B = 0); S1 = 0 < S2 gives A = x1.
    Callers must first reject S2·x2 <= S1·x1 (see `saturation_problem`).
    """
    x1, s1, x2, s2 = (np.asarray(v, dtype=float) for v in (x1, s1, x2, s2))
    none = ((s1 == 0) & (s2 == 0)) | (x1 == 0) | (x2 == 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.sqrt(np.where(s1 > 0, s1 * x1 / np.where(none, 1.0, s2 * x2), 0.0))
        a = np.where(s1 > 0, (x1 - r * x2) / (1 - r), x1)
        b = np.where(s1 > 0, s1 * x1 / (x1 - a) ** 2, s2 * x2 / (x2 - x1) ** 2)
    return np.where(none, 0.0, a), np.where(none, 0.0, b)


def saturation_problem(x1: float, s1: float, x2: float, s2: float) -> str | None:
    """Why two saturation points cannot define a curve, or None (spec §0)."""
    if (s1 == 0 and s2 == 0) or x1 == 0 or x2 == 0:
        return None
    if s1 < 0 or s2 < 0:
        return f"saturation factors must be >= 0 (S1 = {s1:g}, S2 = {s2:g})"
    if not (0 < x1 < x2):
        return f"saturation points need 0 < E1 < E2 (E1 = {x1:g}, E2 = {x2:g})"
    if s2 * x2 <= s1 * x1:
        return f"saturation needs S2·E2 > S1·E1 (S1 = {s1:g} at {x1:g}, S2 = {s2:g} at {x2:g})"
    return None


class LoadPorts(NamedTuple):
    """What a load model reads, arrays (n,).

    Attributes:
      v: bus (load-slot) voltage, network frame, complex p.u.
      flags: the units' discrete states {flag: (n,)} (`LoadModel.flags`).
    """

    v: Array
    flags: States


class LoadModel(DeviceModel):
    """A dynamic load attached to one RAW load record (bus, LID), one row per unit.

    Continuous `states` are integrated with the machines (Heun); discrete `flags` (timers,
    run/stall flags, latches, measured signals) change once per accepted step in `update`,
    after the corrector, from that step's network voltage (one-step latency, as in the
    reference simulators). Every unit has a constant Norton admittance `p["y_norton"]`
    (complex, p.u. system base) folded into the network matrix; the network sees
    y_norton·V − shed·current(V) as the unit's injection correction.
    """

    flags: ClassVar[tuple[str, ...]] = ()
    relaxing: ClassVar[tuple[str, ...]] = ()  # flags that relax from their start by design

    @classmethod
    def ports(cls, signals: Signals, k: Array, flags: States) -> LoadPorts:
        return LoadPorts(v=signals.v_load[k], flags=flags)

    @classmethod
    def init_ports(cls, point: StartPoint, k: Array, labels: tuple[str, ...]) -> LoadSite:
        return point.site.pick(k, labels)

    @classmethod
    def init(cls, p: Params, site: LoadSite) -> Initial:
        """p with y_norton and derived constants, states, flags, output {s0} and the load
        report at site. s0: (n,) complex power the units draw at site.v0, p.u. system base
        (the rest of the bus load stays static); report lines name the unit by
        site.label(k)."""
        raise NotImplementedError

    @classmethod
    def current(cls, p: Params, x: States, z: States, v: Array) -> Array:
        """(n,) complex current drawn at bus voltage v (n,), p.u. system base, before shedding."""
        raise NotImplementedError

    @classmethod
    def shed_current(cls, p: Params, x: States, z: States, v: Array, left: Array) -> Array:
        """(n,) current drawn at the unit's slot when the fraction `left` (n,) of its load
        is connected: left·current (end-use shedding)."""
        return left * cls.current(p, x, z, v)

    @classmethod
    def upstream_injection(cls, p: Params, x: States, z: States, v: Array,
                           left: Array) -> Array | None:
        """(n,) current injected at the load slots p["upstream_slot"] (n,) int, or None (no
        second slot; the default)."""
        return None

    @classmethod
    def rates(cls, p: Params, x: States, ports: LoadPorts) -> tuple[None, States]:
        """(None, rates of the continuous states) at bus voltage ports.v (n,) complex."""
        return None, {}

    @classmethod
    def update(cls, p: Params, x: States, z: States, v: Array, v_old: Array, dt: float) -> States:
        """Flags after an accepted step: v the new, v_old the previous bus voltage (n,)."""
        return z

    @classmethod
    def stiff_rates(cls, p: Params, x: States, z: States) -> dict[tuple[str, str], Array]:
        """{(real state, imaginary state): λ (n,) complex, 1/s} for complex states whose rate
        is stiff and linear in themselves at a fixed bus voltage, d(x_r + j·x_i)/dt ≈
        λ·(x_r + j·x_i) + rest. The step integrates λ exactly (`jaxgrid.dynamics`,
        exponential Heun); none by default."""
        return {}

    @classmethod
    def implicit_blocks(cls) -> tuple[tuple[str, ...], ...]:
        """Blocks of state names, all of one length, whose rates at a fixed bus voltage
        depend only on the block's own states (one motor's E', ψk and speed): the
        linearly implicit step (`jaxgrid.steppers.rosenbrock_heun`) solves each block with
        its own Jacobian. None by default."""
        return ()
