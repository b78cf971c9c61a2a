"""Power flow against references nobody here wrote.

- The voltages stored in PSS/E RAW files are the original tool's solutions:
  PSS/E's default mismatch tolerance is 0.1 MW/Mvar (1e-3 p.u. on 100 MVA) and
  the files store 4-6 decimals, so agreement to 1e-3 p.u. in magnitude is the
  bar the issue sets (we report the actual figures in the note).
- PYPOWER's runpf (MATPOWER's algorithm) on case39 / case300: both solve the
  same equations to 1e-12, so 1e-6 p.u. and 1e-5 rad leave margin only for
  round-off.
- ANDES's power flow on the RAW files it ships (tolerance 1e-6 p.u.).
"""
from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from conftest import SHARED_CASES, andes_cases_dir, stored_mismatch
from experiments.powerflow import main
from jaxgrid import cases
from jaxgrid.io.matpower import from_matpower, load_pypower_case
from jaxgrid.io.raw import parse_raw, read_raw
from jaxgrid.powerflow import PowerFlowOptions, solve

VM_TOL_STORED = 1e-3  # p.u., PSS/E's own convergence tolerance (see module docstring)
VA_TOL_STORED = math.radians(0.6)  # the 300-bus 35 % file was solved loosely (0.48 deg)
VM_TOL_SOLVER, VA_TOL_SOLVER = 1e-6, 1e-5  # p.u., rad: two exact solvers, round-off only
VM_TOL_ANDES, VA_TOL_ANDES = 1e-5, 5e-5  # ANDES stops at 1e-6 p.u. mismatch

# Files whose stored voltages were saved before the data were edited: the
# stored voltages do not satisfy the stored network's equations (checked in
# test_stale_stored_solutions), so they cannot serve as a reference.
STALE = {
    "ieee39/IEEE39bus_multiloads_xfmr4_smallX_v30.raw": 508,
    "ieee39/IEEE39bus_multiloads_xfmr4_smallX_slackmvachange_v33.raw": 508,
    **{f"ieee39/baseCases/IEEE39bus_multiloads_xfmr4_smallX_v30_4load_{kind}{level}.raw": 508
       for kind in ("acperc", "perc") for level in (80, 90, 110, 120)},
    "ieee300/IEEE300Bus_modified_noHVDC_v2.raw": 120,  # HVDC terminal removed
    "ieee300/IEEE300Bus_modified_noHVDC_v23_reduce3bigloads.raw": 10030,  # loads reduced
}
SHARED_RAW = sorted(str(p.relative_to(SHARED_CASES)) for p in SHARED_CASES.rglob("*")
                    if p.suffix.lower() == ".raw")
ANDES_RAW = ["ieee14/ieee14.raw", "ieee39/ieee39.raw", "kundur/kundur.raw", "wscc9/wscc9.raw",
             "wscc9/wscc9_3wxfr.raw", "npcc/npcc.raw", "wecc/wecc.raw", "nordic44/N44_BC.raw"]


def _read(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_raw(path)


def test_reference_file_lists_are_complete():
    """Every RAW under ../shared/cases is covered (20 files) and the andes set exists."""
    assert len(SHARED_RAW) == 21, SHARED_RAW
    for name in ANDES_RAW:
        assert (andes_cases_dir() / name).is_file(), name


@pytest.mark.parametrize("relative", SHARED_RAW)
def test_shared_raw_converges_to_stored_voltages(relative):
    """Each PNNL RAW file parses, converges, and reproduces its stored solution."""
    case = _read(SHARED_CASES / relative)
    result = solve(case)
    assert result.converged and result.max_mismatch < 1e-8
    assert np.all(np.isfinite(result.vm)) and np.all(np.isfinite(result.va))
    if relative in STALE:
        return
    live = case.buses.kind != 4
    d_vm = np.abs(result.vm - case.buses.vm)[live]
    d_va = np.abs(np.angle(np.exp(1j * (result.va - case.buses.va))))[live]
    assert d_vm.max() < VM_TOL_STORED, f"bus {case.buses.number[live][d_vm.argmax()]}"
    assert d_va.max() < VA_TOL_STORED, f"bus {case.buses.number[live][d_va.argmax()]}"


@pytest.mark.parametrize("relative", sorted(STALE))
def test_stale_stored_solutions(relative):
    """The excluded files really are stale: > 0.5 p.u. mismatch at the edited bus."""
    case = _read(SHARED_CASES / relative)
    mismatch = np.abs(stored_mismatch(case))
    bus = case.bus_index(STALE[relative])[0]
    assert mismatch[bus] > 0.5


def test_stale_39bus_by_hand():
    """Independent of our Y-bus: P through the 8-508 transformer (X = 0.003) from the
    stored voltages, V8 V508 sin(d8 - d508) / X, is far above the 522 MW load at 508."""
    case = _read(SHARED_CASES / "ieee39/IEEE39bus_multiloads_xfmr4_smallX_v30.raw")
    i8, i508 = case.bus_index([8, 508])
    vm, va = case.buses.vm, case.buses.va
    p_flow = vm[i8] * vm[i508] * math.sin(va[i8] - va[i508]) / 0.003
    load = case.loads.p_power[case.loads.bus == i508].sum()
    assert load == pytest.approx(5.22)
    assert p_flow > 3 * load


@pytest.mark.parametrize("relative", ANDES_RAW)
def test_andes_raw_converges(relative):
    """The RAW files bundled with andes parse and their power flow converges."""
    result = solve(_read(andes_cases_dir() / relative))
    assert result.converged and result.max_mismatch < 1e-8


@pytest.mark.parametrize("relative", ["ieee14/ieee14.raw", "kundur/kundur.raw", "wscc9/wscc9.raw",
                                      "npcc/npcc.raw", "wecc/wecc.raw"])
def test_andes_raw_stored_voltages(relative):
    """Stored solutions of the andes files are reproduced (ieee14 only with Q limits)."""
    case = _read(andes_cases_dir() / relative)
    result = solve(case)
    assert np.abs(result.vm - case.buses.vm).max() < VM_TOL_STORED
    assert np.abs(result.va - case.buses.va).max() < VA_TOL_STORED


def test_q_limits_matter_on_ieee14():
    """Without PV-to-PQ switching ieee14 misses its stored solution by > 1e-2 p.u."""
    case = _read(andes_cases_dir() / "ieee14/ieee14.raw")
    free = solve(case, PowerFlowOptions(enforce_q_limits=False))
    limited = solve(case)
    assert np.abs(free.vm - case.buses.vm).max() > 1e-2
    assert len(limited.switched_to_pq) > 0
    gen = case.generators
    for b in case.bus_index(list(limited.switched_to_pq)):
        units = gen.in_service & (gen.bus == b)
        q = limited.qg[units].sum()
        assert (math.isclose(q, gen.qmax[units].sum(), abs_tol=1e-9)
                or math.isclose(q, gen.qmin[units].sum(), abs_tol=1e-9))


@pytest.mark.parametrize("relative", ["ieee14/ieee14.raw", "ieee39/ieee39.raw", "kundur/kundur.raw",
                                      "wscc9/wscc9.raw", "npcc/npcc.raw", "wecc/wecc.raw"])
def test_agrees_with_andes_powerflow(relative):
    """Same RAW, ANDES's Newton power flow (no Q limits in either)."""
    import andes

    andes.config_logger(stream_level=50)
    path = andes_cases_dir() / relative
    system = andes.load(str(path), setup=True, no_output=True, default_config=True)
    system.PFlow.run()
    assert system.PFlow.converged
    case = _read(path)
    result = solve(case, PowerFlowOptions(enforce_q_limits=False))
    index = case.bus_index([int(i) for i in system.Bus.idx.v])
    assert np.abs(result.vm[index] - system.Bus.v.v).max() < VM_TOL_ANDES
    assert np.abs(result.va[index] - system.Bus.a.v).max() < VA_TOL_ANDES


def test_three_winding_star_equivalent():
    """wscc9_3wxfr: one 3-winding transformer -> 3 branches to star bus -1; the
    solution from the stored start equals the flat-start solution."""
    case = _read(andes_cases_dir() / "wscc9/wscc9_3wxfr.raw")
    star = case.bus_index(-1)[0]
    legs = case.branches.to_bus == star
    assert legs.sum() == 3 and case.branches.is_transformer[legs].all()
    # Z12 = 0.01+0.1j, Z23 = 0.02+0.2j, Z31 = 0.03+0.3j -> Z1 = 0.01+0.1j, Z3 = 0.02+0.2j
    assert np.allclose(case.branches.x[legs], [0.1, 1e-4, 0.2])
    stored, flat = solve(case), solve(case, PowerFlowOptions(flat_start=True))
    assert np.abs(stored.vm - flat.vm).max() < 1e-8
    assert np.abs(stored.va - flat.va).max() < 1e-8
    assert stored.vm.min() > 0.95


@pytest.mark.parametrize("name", ["case39", "case300"])
def test_matpower_route_matches_pypower(name):
    """MATPOWER data through our reader and solver vs pypower.runpf."""
    from pypower import api as pypower

    ppc = getattr(pypower, name)()
    ppc = {k: np.asarray(v, dtype=float) if k in ("bus", "gen", "branch") else v
           for k, v in ppc.items()}  # pypower's case9-style integer arrays truncate results
    reference, success = pypower.runpf(ppc, pypower.ppoption(VERBOSE=0, OUT_ALL=0, PF_TOL=1e-12))
    assert success
    result = solve(from_matpower(ppc, name), PowerFlowOptions(enforce_q_limits=False, tol=1e-11))
    assert np.abs(result.vm - reference["bus"][:, 7]).max() < VM_TOL_SOLVER
    assert np.abs(result.va - np.radians(reference["bus"][:, 8])).max() < VA_TOL_SOLVER
    base = ppc["baseMVA"]
    assert np.abs(result.pg * base - reference["gen"][:, 1]).max() < 1e-4  # MW
    assert np.abs(result.qg * base - reference["gen"][:, 2]).max() < 1e-4  # Mvar


def test_builtin_cases():
    """Registry: ieee39 has the study's load buses behind transformers, ieee300 is case300."""
    assert {"ieee39", "ieee300"} <= set(cases.names())
    case39 = cases.load("ieee39")
    original = load_pypower_case("case39")
    for bus in (4, 7, 8, 18):
        new = case39.bus_index(500 + bus)[0]
        records = case39.loads.bus == new
        assert sorted(case39.loads.load_id[k] for k in np.flatnonzero(records)) == ["1", "2", "3"]
        moved = original.loads.p_power[original.loads.bus == original.bus_index(bus)[0]].sum()
        assert case39.loads.p_power[records].sum() == pytest.approx(moved)
        assert not (case39.loads.bus == case39.bus_index(bus)[0]).any()
    assert solve(case39).converged
    case300 = cases.load("ieee300")
    assert case300.n_bus == 300 and len(case300.zones) > 1
    with pytest.raises(ValueError, match="unknown case 'ieee9999'.*ieee39"):
        cases.load("ieee9999")


def test_transformer_codes_by_hand():
    """CW=2 (kV), CZ=3 (load loss W, |Z| on 50 MVA), CM=2 (no-load loss W, I0 on 50 MVA)."""
    text = """0, 100.00, 33, 0, 1, 60.00 / hand-made
T1
T2
1,'A', 345.0,3, 1,1,1, 1.0, 0.0
2,'B', 138.0,1, 1,1,1, 1.0, 0.0
0 / END OF BUS DATA
2,'1',1,1,1, 10.0, 2.0, 0,0,0,0, 1
0 / END OF LOAD DATA
0 / END OF FIXED SHUNT DATA
1,'1', 10.0, 0.0, 100.0, -100.0, 1.0, 0, 100.0
0 / END OF GENERATOR DATA
0 / END OF BRANCH DATA
1, 2, 0,'1 ', 2, 3, 2, 50000.0, 0.01, 2,'T', 1
100000.0, 0.1, 50.0
362.25, 345.0, 30.0
138.0, 138.0
0 / END OF TRANSFORMER DATA
Q
"""
    case = parse_raw(text, "hand.raw")
    br = case.branches
    assert br.tap[0] == pytest.approx(362.25 / 345.0)  # CW=2: WINDV1 / bus base kV
    assert br.shift[0] == pytest.approx(math.radians(30.0))
    r_winding = 0.1 / 50.0  # 100 kW load loss / 50 MVA, p.u. on the winding base
    assert br.r[0] == pytest.approx(r_winding * 2.0)  # to the 100 MVA system base
    assert br.x[0] == pytest.approx(math.sqrt(0.1 ** 2 - r_winding ** 2) * 2.0)
    g = 0.05 / 100.0  # 50 kW no-load loss on 100 MVA
    y = 0.01 * 50.0 / 100.0  # 1 % exciting current on 50 MVA
    assert br.g_from[0] == pytest.approx(g)
    assert br.b_from[0] == pytest.approx(-math.sqrt(y ** 2 - g ** 2))


def test_v23_loads_come_from_bus_records(shared_cases):
    """v23 file: 509 bus records, 242 of them with PL/QL != 0 (hand count with awk)."""
    case = _read(shared_cases / "ieee300/IEEE300Bus_modified_noHVDC_v23_reduce3bigloads.raw")
    assert case.n_bus == 509
    assert len(case.loads.bus) == 242
    assert case.skipped == {"transformer adjustment": 60}


def test_cli_json(tmp_path, shared_cases):
    """python -m experiments.powerflow --raw FILE --out pf.json: keys, RAW bus order, values."""
    raw = shared_cases / "ieee39/baseCases/IEEE39bus_multiloads_xfmr4_smallX_v30_allload_per90.raw"
    out = tmp_path / "new_folder" / "pf.json"
    assert main(["--raw", str(raw), "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert set(data) == {"bus_ids", "vm", "va_deg", "converged", "iterations", "max_mismatch_pu"}
    case = _read(raw)
    assert data["bus_ids"] == case.buses.number.tolist()
    assert data["converged"] is True and data["max_mismatch_pu"] < 1e-8
    assert np.abs(np.array(data["vm"]) - case.buses.vm).max() < VM_TOL_STORED
    assert main(["--raw", str(tmp_path / "missing.raw")]) == 2


def test_sparse_jacobian_equals_central_differences():
    """The Newton step's Jacobian (CSR on `jacobian_pattern`, its values from the jitted
    residual program) is the residual's derivative: central differences (h = 1e-6) on the
    PNNL 39-bus file with ZIP loads, at a point off the solution, with P and Q rows masked as
    a solve masks them. Float64 differences are exact to about h² (third derivatives of order
    |Y| ~ 1e2 p.u.: 1e-10) plus round-off (1e-16 × 1e2 / h: 1e-8), so 1e-6 of the largest
    entry (about 1e3) leaves margin and still catches a misplaced entry."""
    import jax
    import scipy.sparse

    from jaxgrid.case import PQ, PV
    from jaxgrid.powerflow import (_residual_and_jacobian, admittance_matrix, bus_loads,
                                   jacobian_pattern)

    case = _read(SHARED_CASES / "ieee39/IEEE39bus_multiloads_xfmr4_smallX_v30.raw")
    n = case.n_bus
    rng = np.random.default_rng(0)
    va = case.buses.va + 0.05 * rng.standard_normal(n)
    vm = case.buses.vm * (1.0 + 0.02 * rng.standard_normal(n))
    kind = case.buses.kind
    pattern = jacobian_pattern(admittance_matrix(case))
    masks = ((kind == PQ) | (kind == PV), kind == PQ)
    with jax.enable_x64(True):
        def residual_and_jacobian(va, vm):
            out = jax.jit(_residual_and_jacobian)(
                va, vm, pattern, np.zeros(n, complex), bus_loads(case), *masks,
                case.buses.va, case.buses.vm)
            return tuple(map(np.asarray, out))

        _, values = residual_and_jacobian(va, vm)
        x, h = np.concatenate([va, vm]), 1e-6
        columns = []
        for k in range(2 * n):
            step = np.zeros(2 * n)
            step[k] = h
            up, down = (residual_and_jacobian(*np.split(x + s, 2))[0] for s in (step, -step))
            columns.append((up - down) / (2 * h))
    assert masks[0].sum() < n and masks[1].sum() < n, "set-point rows present"
    sparse = scipy.sparse.csr_matrix((values, pattern.indices, pattern.indptr),
                                     shape=(2 * n, 2 * n)).toarray()
    finite = np.stack(columns, axis=1)
    assert np.abs(sparse - finite).max() <= 1e-6 * np.abs(finite).max()
