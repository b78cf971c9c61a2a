"""AC power flow: full Newton-Raphson in polar form, in JAX, float64.

The unknowns are every bus's angle and magnitude (2 n_bus). Each bus contributes
a P row and a Q row; a row whose quantity is not specified is replaced by the
set-point equation (slack: `va = va_set`; PV and slack: `vm = vm_set`;
isolated buses are pinned), so the Jacobian has one static sparsity pattern (the
admittance matrix's nonzeros and diagonal, `jacobian_pattern`). PV-to-PQ switching
on reactive limits then changes only boolean masks (data), and the residual with the
Jacobian's values is one jitted JAX program per case size. Jacobian: the analytic
polar derivatives of S = V conj(Y V) (as in MATPOWER's dSbus_dV), plus the voltage
dependence of ZIP loads. Each Newton step is a sparse LU solve on the host (SciPy's
SuperLU): the ACTIVSg2000 power flow took 9.5-10.5 s with a dense LU of its 4 000 × 4 000
Jacobian (docs/performance.md).

Conventions (see `jaxgrid.case`): p.u. on the system base, angles in radians.
Loads are P + jQ = S_power + S_current |V| + S_impedance |V|^2.

Command line: `python -m experiments.powerflow`.
"""
from __future__ import annotations

import dataclasses
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from jaxgrid.case import ISOLATED, PQ, PV, SLACK, Case, build_case, to_rows


class PowerFlowError(RuntimeError):
    """The Newton iteration did not converge; says where the mismatch is largest."""


@dataclasses.dataclass(frozen=True)
class PowerFlowOptions:
    """Power-flow settings.

    Attributes:
      tol: convergence tolerance on the largest P/Q mismatch, p.u. (1e-8 p.u. = 1 W at 100 MVA).
      max_iter: Newton iterations per solve.
      flat_start: start from vm = 1 (set points at PV/slack), va = slack angle,
        instead of the voltages stored in the case.
      enforce_q_limits: switch PV buses whose generators leave [Qmin, Qmax] to PQ
        with Q at the limit, and back to PV when the voltage returns to the
        set-point side of the limit; solve again until no bus changes (as PSS/E).
      max_switch_rounds: solves allowed for PV-to-PQ switching.
    """

    tol: float = 1e-8
    max_iter: int = 30
    flat_start: bool = False
    enforce_q_limits: bool = True
    max_switch_rounds: int = 20


@dataclasses.dataclass(frozen=True)
class PowerFlowResult:
    """A solved operating point.

    Attributes:
      case: the case that was solved.
      vm: (n_bus,) voltage magnitude, p.u. (0 at isolated buses).
      va: (n_bus,) voltage angle, radians (0 at isolated buses).
      pg, qg: (n_gen,) generator output, p.u. system base (0 when out of service).
      bus_kind: (n_bus,) bus types after PV-to-PQ switching.
      switched_to_pq: external numbers of PV buses held at a reactive limit.
      iterations: Newton iterations, summed over switching rounds.
      max_mismatch: largest P/Q mismatch at the solution, p.u.
      converged: True (a failed solve raises PowerFlowError instead).
    """

    case: Case
    vm: np.ndarray
    va: np.ndarray
    pg: np.ndarray
    qg: np.ndarray
    bus_kind: np.ndarray
    switched_to_pq: tuple[int, ...]
    iterations: int
    max_mismatch: float
    converged: bool = True

    def to_json(self) -> dict:
        """The CLI's JSON: buses in the file's order (three-winding star buses left out)."""
        keep = self.case.buses.number > 0
        return {
            "bus_ids": self.case.buses.number[keep].tolist(),
            "vm": self.vm[keep].tolist(),
            "va_deg": np.degrees(self.va[keep]).tolist(),
            "converged": self.converged,
            "iterations": self.iterations,
            "max_mismatch_pu": self.max_mismatch,
        }


# --------------------------------------------------------------------------- #
# Host-side assembly (NumPy, float64)
# --------------------------------------------------------------------------- #

def active_branches(case: Case) -> np.ndarray:
    """(n_branch,) bool: in service and not touching an isolated bus."""
    br, kind = case.branches, case.buses.kind
    return br.in_service & (kind[br.from_bus] != ISOLATED) & (kind[br.to_bus] != ISOLATED)


def admittance_matrix(case: Case) -> np.ndarray:
    """Dense bus admittance matrix (n_bus, n_bus), complex128, p.u.

    Branches as pi models with the ratio tap * exp(j shift) on the from side,
    bus-side branch-end shunts, and in-service shunts. Loads are not included.
    """
    br = case.branches
    on = active_branches(case)
    ys = 1.0 / (br.r + 1j * br.x)
    ratio = br.tap * np.exp(1j * br.shift)
    y_ff = (ys + 0.5j * br.b) / np.abs(ratio) ** 2 + br.g_from + 1j * br.b_from
    y_tt = ys + 0.5j * br.b + br.g_to + 1j * br.b_to
    y_ft = -ys / np.conj(ratio)
    y_tf = -ys / ratio
    n = case.n_bus
    ybus = np.zeros((n, n), dtype=np.complex128)
    f, t = br.from_bus[on], br.to_bus[on]
    np.add.at(ybus, (f, f), y_ff[on])
    np.add.at(ybus, (t, t), y_tt[on])
    np.add.at(ybus, (f, t), y_ft[on])
    np.add.at(ybus, (t, f), y_tf[on])
    sh = case.shunts
    np.add.at(ybus, (sh.bus[sh.in_service], sh.bus[sh.in_service]),
              (sh.g + 1j * sh.b)[sh.in_service])
    return ybus


def bus_loads(case: Case) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-bus ZIP load at 1 p.u.: (S_power, S_current, S_impedance), each (n_bus,) complex."""
    ld, n = case.loads, case.n_bus
    on = ld.in_service

    def total(p, q):
        out = np.zeros(n, dtype=np.complex128)
        np.add.at(out, ld.bus[on], (p + 1j * q)[on])
        return out

    return (total(ld.p_power, ld.q_power), total(ld.p_current, ld.q_current),
            total(ld.p_impedance, ld.q_impedance))


def _bus_sum(case: Case, values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    out = np.zeros(case.n_bus)
    np.add.at(out, case.generators.bus[mask], values[mask])
    return out


# --------------------------------------------------------------------------- #
# Newton iteration (JAX equations, SciPy sparse LU)
# --------------------------------------------------------------------------- #

class JacobianPattern(NamedTuple):
    """The sparsity of the power-flow Jacobian (host, built once per solve): the admittance
    matrix's nonzeros and its diagonal, E entries in row-major order, and the CSR structure of
    the (2 n_bus, 2 n_bus) Jacobian whose P row r and Q row n + r hold, for each entry (r, c),
    the columns c (angle) and n + c (magnitude).

    Attributes:
      rows, cols: (E,) int, the entries' buses.  y: (E,) complex128, Y[rows, cols], p.u.
      order: (4E,) int, CSR position -> index into the stacked entry values [dP/dva, dP/dvm,
        dQ/dva, dQ/dvm] (each (E,)).  indices: (4E,) int32 columns.  indptr: (2 n_bus + 1,)
        int32 row starts.
    """

    rows: np.ndarray
    cols: np.ndarray
    y: np.ndarray
    order: np.ndarray
    indices: np.ndarray
    indptr: np.ndarray


def jacobian_pattern(ybus: np.ndarray) -> JacobianPattern:
    """The `JacobianPattern` of a dense admittance matrix (n, n)."""
    n = ybus.shape[0]
    nonzero = ybus != 0
    nonzero[np.diag_indices(n)] = True  # the set-point rows' identity entries
    rows, cols = np.nonzero(nonzero)
    count = rows.size
    per_row = np.bincount(rows, minlength=n)
    starts = np.concatenate([[0], np.cumsum(per_row)])
    entry = np.arange(count)
    angle = starts[rows] + entry  # row r's angle columns, then its magnitude columns
    magnitude = angle + per_row[rows]
    order, indices = np.empty(4 * count, int), np.empty(4 * count, np.int32)
    for offset, position, block, column in ((0, angle, 0, cols), (0, magnitude, 1, n + cols),
                                            (2 * count, angle, 2, cols),
                                            (2 * count, magnitude, 3, n + cols)):
        order[offset + position] = block * count + entry
        indices[offset + position] = column
    indptr = np.concatenate([2 * starts[:-1], 2 * count + 2 * starts]).astype(np.int32)
    return JacobianPattern(rows, cols, ybus[rows, cols], order, indices, indptr)


def _residual_and_jacobian(va, vm, pattern, s_gen, s_load, p_row, q_row, va_set, vm_set):
    """Stacked residual (2n,) and the Jacobian's CSR values (4E,) of the masked power-flow
    equations, on `pattern` (a `JacobianPattern` of jnp arrays)."""
    s_power, s_current, s_impedance = s_load
    rows, cols, y = pattern.rows, pattern.cols, pattern.y
    n = vm.shape[0]
    v = vm * jnp.exp(1j * va)
    i_bus = jax.ops.segment_sum(y * v[cols], rows, num_segments=n)
    s_bus = v * jnp.conj(i_bus)
    mismatch = s_bus - s_gen + s_power + s_current * vm + s_impedance * vm ** 2
    unit = v / vm
    diagonal = rows == cols
    ds_dva = 1j * v[rows] * jnp.conj(jnp.where(diagonal, i_bus[rows], 0.0) - y * v[cols])
    ds_dvm = v[rows] * jnp.conj(y * unit[cols]) + jnp.where(
        diagonal, (jnp.conj(i_bus) * unit + s_current + 2 * s_impedance * vm)[rows], 0.0)
    one = diagonal.astype(vm.dtype)
    p, q = p_row[rows], q_row[rows]
    values = jnp.concatenate([jnp.where(p, ds_dva.real, one), jnp.where(p, ds_dvm.real, 0.0),
                              jnp.where(q, ds_dva.imag, 0.0), jnp.where(q, ds_dvm.imag, one)])
    residual = jnp.concatenate([jnp.where(p_row, mismatch.real, va - va_set),
                                jnp.where(q_row, mismatch.imag, vm - vm_set)])
    return residual, values[pattern.order]


_evaluate = jax.jit(_residual_and_jacobian)


def newton(va, vm, pattern, s_gen, s_load, p_row, q_row, va_set, vm_set, tol, max_iter):
    """Newton-Raphson until max |residual| < tol, max_iter, or a non-finite step.

    The residual and the Jacobian's values are one jitted JAX program (float64, under the
    caller's `jax.enable_x64`); each step is a sparse LU solve on the host
    (`scipy.sparse.linalg.spsolve`, SuperLU: the sparse factors of a grid's Jacobian, not a
    dense LU's n³ work).
    Args: va, vm (n,) start point (rad, p.u.); pattern: the admittance matrix's
    `JacobianPattern`; s_gen (n,) specified generation; s_load (3 x (n,)) ZIP load; p_row,
    q_row (n,) bool, True where the P / Q balance is enforced; va_set, vm_set (n,) set
    points elsewhere (NumPy arrays). Returns (va, vm, iterations, residual (2n,)) of the last
    finite iterate, NumPy; iterations is max_iter after a non-finite step.
    """
    on_device = JacobianPattern(*map(jnp.asarray, pattern))
    args = [on_device] + [jax.tree.map(jnp.asarray, a)
                          for a in (s_gen, s_load, p_row, q_row, va_set, vm_set)]
    residual, jac = map(np.asarray, _evaluate(va, vm, *args))
    n, it = va.shape[0], 0
    while np.max(np.abs(residual)) > tol and it < max_iter:
        matrix = scipy.sparse.csr_matrix((jac, pattern.indices, pattern.indptr),
                                         shape=(2 * n, 2 * n))
        with warnings.catch_warnings():  # a singular Jacobian: nan steps, stopped below
            warnings.simplefilter("ignore", scipy.sparse.linalg.MatrixRankWarning)
            step = scipy.sparse.linalg.spsolve(matrix, -residual)
        va_new, vm_new = va + step[:n], vm + step[n:]
        res_new, jac_new = map(np.asarray, _evaluate(va_new, vm_new, *args))
        if not (np.all(np.isfinite(res_new)) and np.all(vm_new > 0)):
            return va, vm, max_iter, residual  # the last good iterate
        va, vm, residual, jac, it = va_new, vm_new, res_new, jac_new, it + 1
    return va, vm, it, residual


# --------------------------------------------------------------------------- #
# Driver (host): set points, start, PV-to-PQ switching, generator dispatch
# --------------------------------------------------------------------------- #

def _set_points(case: Case):
    """Effective bus types, voltage set points and specified generation."""
    gen, bus = case.generators, case.buses
    on = gen.in_service & (bus.kind[gen.bus] != ISOLATED)
    kind = bus.kind.copy()
    has_gen = _bus_sum(case, np.ones(len(gen.bus)), on) > 0
    kind[(kind == PV) & ~has_gen] = PQ  # PSS/E: a type-2 bus without a machine is type 1
    vm_set = np.where(bus.vm > 0, bus.vm, 1.0)
    for k in np.flatnonzero(on)[::-1]:  # first in-service machine's VS wins
        vm_set[gen.bus[k]] = gen.vset[k]
    s_gen = _bus_sum(case, gen.pg, on) + 1j * _bus_sum(case, gen.qg, on)
    return kind, vm_set, s_gen, on


def _dispatch(case: Case, s_gen_bus: np.ndarray, on: np.ndarray):
    """Split each bus's generation over its in-service machines.

    P: stored values, the slack bus's difference to its first machine.
    Q: in proportion to each machine's reactive range (so all sit at a limit together).
    """
    gen = case.generators
    pg = np.where(on, gen.pg, 0.0)
    for b in np.flatnonzero(case.buses.kind == SLACK):
        units = np.flatnonzero(on & (gen.bus == b))
        if units.size:
            pg[units[0]] += s_gen_bus[b].real - pg[units].sum()
    qmax_bus, qmin_bus = _bus_sum(case, gen.qmax, on), _bus_sum(case, gen.qmin, on)
    count = _bus_sum(case, np.ones(len(gen.bus)), on)
    span = qmax_bus - qmin_bus
    b = gen.bus
    share = np.where(span[b] > 0,
                     (s_gen_bus.imag[b] - qmin_bus[b]) / np.where(span[b] > 0, span[b], 1.0), 0.0)
    qg = np.where(span[b] > 0, gen.qmin + share * (gen.qmax - gen.qmin),
                  s_gen_bus.imag[b] / np.maximum(count[b], 1))
    return pg, np.where(on, qg, 0.0)


def with_reactive_room(case: Case) -> Case:
    """`case` with each generator's [Qmin, Qmax] widened to hold its reactive output in the
    power flow solved without reactive limits, so the set points hold at a heavier load (the
    PNNL 300-bus `baseCases` files raise QMAX so, on 36-49 units). PowerFlowError if even
    that power flow does not converge."""
    flow = solve(case, PowerFlowOptions(enforce_q_limits=False))
    rows = to_rows(case)
    for gen, q in zip(rows["generators"], flow.qg):
        gen.update(qmax=max(gen["qmax"], float(q)), qmin=min(gen["qmin"], float(q)))
    return build_case(**rows)


def solve(case: Case, options: PowerFlowOptions = PowerFlowOptions()) -> PowerFlowResult:
    """Solve the AC power flow of `case`; raises PowerFlowError if it does not converge."""
    kind, vm_set, s_gen, on = _set_points(case)
    isolated = kind == ISOLATED
    va_set = np.where(isolated, 0.0, case.buses.va)
    vm_set = np.where(isolated, 1.0, vm_set)
    if options.flat_start:
        va0 = np.full(case.n_bus, case.buses.va[kind == SLACK][0])
        vm0 = np.where(kind == PQ, 1.0, vm_set)
    else:
        va0, vm0 = va_set.copy(), np.where(kind == PQ, np.where(case.buses.vm > 0,
                                                                  case.buses.vm, 1.0), vm_set)
    s_load = bus_loads(case)
    qmax = _bus_sum(case, case.generators.qmax, on)
    qmin = _bus_sum(case, case.generators.qmin, on)
    limited = np.zeros(case.n_bus, dtype=int)  # +1 held at Qmax, -1 at Qmin
    iterations = 0
    ybus_host = admittance_matrix(case)
    with jax.enable_x64(True):
        pattern = jacobian_pattern(ybus_host)
        for _ in range(options.max_switch_rounds):
            p_row = (kind == PQ) | (kind == PV)
            q_row = kind == PQ
            va, vm, it, residual = newton(va0, vm0, pattern, s_gen, s_load, p_row, q_row,
                                          va_set, vm_set, options.tol, options.max_iter)
            iterations += int(it)
            _raise_if_failed(case, residual, int(it), options)
            v = vm * np.exp(1j * va)
            s_load_v = s_load[0] + s_load[1] * vm + s_load[2] * vm ** 2
            s_gen_bus = v * np.conj(ybus_host @ v) + s_load_v
            if not options.enforce_q_limits:
                break
            q = s_gen_bus.imag
            hit_max = (kind == PV) & (q > qmax + options.tol)
            hit_min = (kind == PV) & (q < qmin - options.tol)
            release = ((limited > 0) & (vm > vm_set + options.tol)) | (
                (limited < 0) & (vm < vm_set - options.tol))
            if not (hit_max.any() or hit_min.any() or release.any()):
                break
            limited = np.where(hit_max, 1, np.where(hit_min, -1, np.where(release, 0, limited)))
            kind = np.where(limited != 0, PQ, np.where(release, PV, kind))
            s_gen = s_gen.real + 1j * np.where(limited > 0, qmax, np.where(
                limited < 0, qmin, s_gen.imag))
            va0, vm0 = va, vm
        else:
            raise PowerFlowError(f"{case.source}: PV-to-PQ switching did not settle in "
                                 f"{options.max_switch_rounds} rounds")
    pg, qg = _dispatch(case, s_gen_bus, on)
    vm = np.where(isolated, 0.0, vm)
    va = np.where(isolated, 0.0, va)
    return PowerFlowResult(case=case, vm=vm, va=va, pg=pg, qg=qg, bus_kind=kind,
                           switched_to_pq=tuple(case.buses.number[limited != 0].tolist()),
                           iterations=iterations,
                           max_mismatch=float(np.max(np.abs(residual))))


def _raise_if_failed(case: Case, residual: np.ndarray, iterations: int,
                     options: PowerFlowOptions) -> None:
    worst = int(np.argmax(np.abs(residual)))
    largest = float(np.abs(residual[worst]))
    if largest <= options.tol:
        return
    n = case.n_bus
    bus = case.buses.number[worst % n]
    part = "P" if worst < n else "Q"
    raise PowerFlowError(
        f"{case.source}: power flow did not converge in {iterations} iterations: "
        f"largest mismatch {largest:.3e} p.u. ({part}) at bus {bus}")
