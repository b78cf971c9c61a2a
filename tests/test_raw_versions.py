"""RAW files read as they are written: v34 and v35 layouts, a first line without REV, a file
that ends after its last non-empty section (`jaxgrid.io.raw`).

One small network is written here in the v33, v34 and v35 layouts (field positions from the
PSS/E POM as GridPACK's PTI33/34/35 parsers and powsybl's v35 records read them); every
layout must give the same tables. The real files are GridPACK's (its source tarball
../shared/reference/gridpack/gridpack-src.tar.gz, `conftest.gridpack_data`):
the WECC 240-bus v34 case, the Texas 2000-bus v33 case without REV and the 9-bus v23 case
that ends before its FACTS section.
"""
from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from conftest import stored_mismatch
from jaxgrid.case import CaseError
from jaxgrid.io.raw import parse_raw, raw_version, read_raw
from jaxgrid.powerflow import solve

RATINGS = ", ".join(["100.0"] * 12)  # v34+: 12 ratings
ZERO_RATINGS = ", ".join(["0.0"] * 11)


def network(version: int, *, rev: bool = True, titles: tuple[str, str] = ("T1", "T2")) -> str:
    """A 3-bus network with a load (and, v34+, distributed generation that nets it to the v33
    load), a fixed and a switched shunt, a generator, a line, two breakers (a v33 line of X =
    5e-4 p.u. and an open one of THRSHZ), a transformer, an impedance-correction table and
    a GNE device in the layout of `version` (33, 34 or 35)."""
    new = version >= 34
    head = f"0, 100.00, {version}, 0, 1, 60.00" if rev else "0, 100.00"
    lines = [f"{head} / test network", *titles]
    if new:
        lines += ["@! system-wide data", "GENERAL, THRSHZ=0.0001, PQBRAK=0.7, BLOWUP=5.0",
                  'RATING, 1, "RATE1 ", "RATING SET 1"', "0 / END OF SYSTEM-WIDE DATA"]
    lines += ["@!   I,'NAME',BASKV,IDE,AREA,ZONE,OWNER,VM,VA"] if new else []
    lines += ["1,'SLACK', 230.0, 3, 1, 1, 1, 1.02, 0.0",
              "2,'MID',   230.0, 1, 1, 1, 1, 1.00, -2.0",
              "3,'LOW',   115.0, 1, 1, 1, 1, 0.99, -4.0",
              "0 / END OF BUS DATA, BEGIN LOAD DATA"]
    load = "3,'1', 1, 1, 1, {p}, {q}, 5.0, 0.0, 0.0, -3.0, 1, 1, 0"
    lines += [load.format(p=50.0, q=10.0) + ", 10.0, 2.0, 1" if new
              else load.format(p=40.0, q=8.0)]
    lines += ["0 / END OF LOAD DATA, BEGIN FIXED SHUNT DATA", "2,'1', 1, 0.0, 5.0",
              "0 / END OF FIXED SHUNT DATA, BEGIN GENERATOR DATA"]
    gen = ["1", "'1'", "60.0", "5.0", "100.0", "-100.0", "1.02", "0", "100.0", "0.0", "0.2",
           "0.0", "0.0", "1.0", "1", "100.0", "200.0", "0.0"]
    if version == 35:
        gen.insert(8, "0")  # NREG after IREG
        gen.append("0")  # BASLOD
    elif version == 34:
        gen += ["1", "1.0", "0", "1.0", "0", "1.0", "0", "1.0", "0", "1.0", "0"]  # ..., NREG
    lines += [", ".join(gen), "0 / END OF GENERATOR DATA, BEGIN BRANCH DATA"]
    shunts = "0.001, 0.002, 0.001, 0.002, 1"
    if new:
        lines += [f"1, 2,'1', 0.01, 0.1, 0.02,'LINE 1-2', {RATINGS}, {shunts}, 1, 0.0, 1, 1.0",
                  "0 / END OF BRANCH DATA, BEGIN SYSTEM SWITCHING DEVICE DATA",
                  f"1, 2,'@1', 0.0005, {RATINGS}, 1, 1, 1, 2, 'BREAKER 1'",
                  f"1, 2,'@2', 0.0, {RATINGS}, 0, 0, 1, 2, 'BREAKER 2'",
                  "0 / END OF SYSTEM SWITCHING DEVICE DATA, BEGIN TRANSFORMER DATA"]
    else:
        lines += [f"1, 2,'1', 0.01, 0.1, 0.02, 100, 100, 100, {shunts}",
                  "1, 2,'@1', 0.0, 0.0005, 0.0, 0, 0, 0, 0, 0, 0, 0, 1",
                  "1, 2,'@2', 0.0, 0.0001, 0.0, 0, 0, 0, 0, 0, 0, 0, 0",
                  "0 / END OF BRANCH DATA, BEGIN TRANSFORMER DATA"]
    # winding 1: COD1 = 0; in v34+ RATE1-4 (where v33 keeps COD1) is not 0
    winding = (f"1.025, 0.0, 5.0, 100.0, 100.0, 100.0, 250.0, {ZERO_RATINGS[:-5]}, 0, 0, 0, "
               "1.1, 0.9, 1.1, 0.9, 33, 0, 0.0, 0.0, 0.0" if new else
               "1.025, 0.0, 5.0, 100.0, 100.0, 100.0, 0, 0, 1.1, 0.9, 1.1, 0.9, 33, 0, 0, 0, 0")
    lines += ["@!   I,J,K,'CKT',CW,CZ,CM,MAG1,MAG2,NMETR,'NAME',STAT"] if new else []
    lines += ["2, 3, 0,'1', 1, 1, 1, 0.001, -0.002, 2,'T23', 1, 1, 1.0",
              "0.002, 0.05, 100.0", winding, "1.0, 0.0",
              "0 / END OF TRANSFORMER DATA, BEGIN AREA DATA", "1, 0, 0.0, 10.0,'AREA1'",
              "0 / END OF AREA DATA, BEGIN TWO-TERMINAL DC DATA",
              "0 / END OF TWO-TERMINAL DC DATA, BEGIN VSC DC LINE DATA",
              "0 / END OF VSC DC LINE DATA, BEGIN IMPEDANCE CORRECTION DATA"]
    points = [(0.9 + 0.05 * k, 1.1 - 0.03 * k, 0.0) for k in range(7)]
    if new:  # six points a line, then the seventh and the closing 0.0, 0.0, 0.0 point
        lines += ["1, " + ", ".join(f"{t}, {f}, {g}" for t, f, g in points[:6]),
                  ", ".join(f"{t}, {f}, {g}" for t, f, g in points[6:]) + ", 0.0, 0.0, 0.0"]
    else:
        lines += ["1, " + ", ".join(f"{t}, {f}" for t, f, _ in points)]
    lines += ["0 / END OF IMPEDANCE CORRECTION DATA, BEGIN MULTI-TERMINAL DC DATA",
              "0 / END OF MULTI-TERMINAL DC DATA, BEGIN MULTI-SECTION LINE DATA",
              "0 / END OF MULTI-SECTION LINE DATA, BEGIN ZONE DATA", "1,'ZONE1'",
              "0 / END OF ZONE DATA, BEGIN INTER-AREA TRANSFER DATA",
              "0 / END OF INTER-AREA TRANSFER DATA, BEGIN OWNER DATA", "1,'OWNER1'",
              "0 / END OF OWNER DATA, BEGIN FACTS DEVICE DATA",
              "0 / END OF FACTS DEVICE DATA, BEGIN SWITCHED SHUNT DATA"]
    shunt = ["3", "1", "0", "1", "1.05", "0.95", "0", "100.0", "''", "12.0", "1", "12.0"]
    if version == 35:
        shunt[1:1] = ["'1'"]  # ID
        shunt[8:8] = ["0"]  # NREG after SWREG
        shunt[12:12] = ["1"]  # S1 before N1
    elif version == 34:
        shunt.append("0")  # NREG
    lines += [", ".join(shunt), "0 / END OF SWITCHED SHUNT DATA, BEGIN GNE DATA",
              "'GNE1', 'MYMODEL', 1, 3, 2, 1, 0", "1, 1, 0", "0.5, 0.25", "7",
              "0 / END OF GNE DATA, BEGIN INDUCTION MACHINE DATA",
              "0 / END OF INDUCTION MACHINE DATA"]
    if new:
        lines += ["1, 'SUB1', 0.0, 0.0, 0.1",
                  "1, 'NODE1', 2, 1, 1.0, 0.0", "0 / END OF SUBSTATION NODE DATA",
                  "1, 2, '1', 'SW1', 2, 1, 1, 0.0001, 0.0, 0.0, 0.0",
                  "0 / END OF SUBSTATION SWITCHING DEVICE DATA",
                  "2, 1, 'B', '1'", "0 / END OF SUBSTATION TERMINAL DATA",
                  "0 / END OF SUBSTATION DATA"]
    return "\n".join(lines + ["Q", ""])


def tables(case) -> dict[str, np.ndarray]:
    """Every column of the case's tables except source lines, by 'table.column'."""
    out = {}
    for table in ("buses", "loads", "shunts", "generators", "branches"):
        value = getattr(case, table)
        for field in dataclasses.fields(value):
            if field.name != "line":
                out[f"{table}.{field.name}"] = np.asarray(getattr(value, field.name))
    return out


def quiet_parse(text: str, source: str, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return parse_raw(text, source, **kwargs)


def assert_same_tables(case, reference) -> None:
    got, want = tables(case), tables(reference)
    assert got.keys() == want.keys()
    for key, value in want.items():
        if value.dtype.kind in "fcib":
            # the same decimal text read; float64 round-off of the unit conversions only
            np.testing.assert_allclose(got[key], value, rtol=1e-12, atol=1e-15, err_msg=key)
        else:
            assert got[key].tolist() == value.tolist(), key


@pytest.fixture(scope="module")
def v33():
    return quiet_parse(network(33), "net33.raw")


@pytest.mark.parametrize("version", [34, 35])
def test_v34_v35_layouts_give_the_v33_tables(version, v33):
    case = quiet_parse(network(version), f"net{version}.raw")
    assert_same_tables(case, v33)
    # the open breaker's X = 0 becomes THRSHZ; nothing counted as tap control (RATE1-4)
    assert any("switching device 1-2 ckt '@2': X = 0 p.u. is below THRSHZ" in n
               for n in case.notes), case.notes
    assert any("DGENP = 10 MW, DGENQ = 2 Mvar (DGENM on) taken off" in n for n in case.notes)
    skipped = {k: v for k, v in case.skipped.items() if k not in ("system-wide", "substation")}
    assert skipped == v33.skipped == {"impedance correction": 1, "gne": 1}, case.skipped
    assert case.skipped["system-wide"] == 2 and case.skipped["substation"] == 1


def test_v34_without_system_wide_section(v33):
    """Some writers leave the v34 system-wide data out: the bus records follow the titles."""
    text = network(34).replace("GENERAL, THRSHZ=0.0001, PQBRAK=0.7, BLOWUP=5.0\n", "").replace(
        'RATING, 1, "RATE1 ", "RATING SET 1"\n', "").replace("0 / END OF SYSTEM-WIDE DATA\n", "")
    case = quiet_parse(text, "nosys.raw")
    assert_same_tables(case, v33)
    assert "nosys.raw:6: no system-wide data section: the bus data begin here" in case.notes


def test_no_rev_read_by_its_bus_records(v33, tmp_path):
    """A v33 file whose first line has no REV and whose title lines are blank (as
    dsa/case_ACTIVSg2000_1.raw): the bus records' layout says v33 (noted); a v23 file
    without REV stays v23 without a note."""
    case = quiet_parse(network(33, rev=False, titles=("", "")), "norev.raw")
    assert_same_tables(case, v33)
    assert case.notes == ("norev.raw:1: case identification has no REV; read as v33, the "
                          "layout of the bus record at line 4",)
    v23 = "0  100.000\nT1\nT2\n1, 3, 0, 0, 0, 0, 1, 1.0, 0.0, 'A', 230.0, 1\n0\n0\n0\nQ\n"
    path = tmp_path / "v23.raw"
    path.write_text(v23)
    assert raw_version(path) == 23 and read_raw(path).notes == ()


def test_no_rev_and_no_bus_layout_asks_for_the_version():
    text = network(34, rev=False)
    with pytest.raises(CaseError, match=r"^norev34\.raw:1: case identification has no REV .*"
                                        r"give it \(read_raw\(path, version=34\)\)"):
        quiet_parse(text, "norev34.raw")
    assert tables(quiet_parse(text, "norev34.raw", version=34)).keys()


@pytest.mark.parametrize("cut, where", [
    ("0 / END OF OWNER DATA, BEGIN FACTS DEVICE DATA", "before the facts data"),
    ("0 / END OF FACTS DEVICE DATA, BEGIN SWITCHED SHUNT DATA", "before the switched shunt data"),
    ("3, 1, 0, 1, 1.05, 0.95, 0, 100.0, '', 12.0, 1, 12.0",
     "in the switched shunt data, without its closing '0' line"),
])
def test_file_ending_after_its_last_section(cut, where, v33):
    """Cut after a section's `0` line (and a blank line) or inside a section after a whole
    record: what was read stands, the rest is empty, and a note says where it ended."""
    full = network(33)
    end = full.index(cut) + len(cut)
    text = full[:end] + "\n\n"
    case = quiet_parse(text, "cut.raw")
    n_lines = len(text.splitlines())
    note = [n for n in case.notes if "the file ends" in n]
    assert note and note[0].startswith(f"cut.raw:{n_lines}: the file ends {where};"), case.notes
    if "switched shunt" in where and "in the" in where:
        assert_same_tables(case, v33)


# --------------------------------------------------------------------------- #
# GridPACK's files
# --------------------------------------------------------------------------- #

# Stored solutions: VM with 5 decimals, VA with 4 (1.7e-6 rad); over the smallest series
# impedance of these files (X = 1e-4 p.u.) that rounding moves a branch flow by up to
# ~(5e-6 + 1.7e-6)/1e-4 = 0.07 p.u., so a stored solution "satisfies" the data to 0.1 p.u.
STORED_MISMATCH = 0.1
VM_TOL_STORED = 1e-3  # p.u.: PSS/E's default mismatch tolerance (test_powerflow)


@pytest.mark.filterwarnings("ignore::jaxgrid.io.raw.RawWarning")  # tap control, as v33
def test_wecc240_v34(gridpack_data):
    """The v34 WECC 240-bus case: its stored solution satisfies our reading of every branch,
    transformer, shunt and generator (0.1 p.u., rounding) except at the four buses whose
    loads were raised by 500 MW + 100 Mvar after it was solved (there the mismatch is
    exactly that load); the power flow converges."""
    case = read_raw(gridpack_data / "raw" / "240busWECC_2018_PSS_fixedshunt.raw")
    assert raw_version(gridpack_data / "raw" / "240busWECC_2018_PSS_fixedshunt.raw") == 34
    assert case.n_bus == 243  # 240 buses and three star points
    mismatch = stored_mismatch(case)
    stale = case.bus_index([1002, 1003, 1004, 1101])
    np.testing.assert_allclose(mismatch[stale], 5.0 + 1.0j, atol=0.01)
    others = np.delete(np.abs(mismatch), stale)
    assert others.max() < STORED_MISMATCH, f"{others.max():.3f} p.u."
    assert solve(case).converged


@pytest.mark.filterwarnings("ignore::jaxgrid.io.raw.RawWarning")  # inter-area transfer
def test_texas2000_without_rev_reads_as_v33(gridpack_data):
    """dsa/case_ACTIVSg2000_1.raw: no REV, blank titles. Read as v33 from its bus records,
    its buses, loads, shunts and generators parse; it is then refused, rightly, for
    repeating circuit 'BL' of branch 1001-1064 (two identical records)."""
    path = gridpack_data / "dsa" / "case_ACTIVSg2000_1.raw"
    assert raw_version(path) == 33
    with pytest.raises(CaseError, match=r"case_ACTIVSg2000_1\.raw:3827: branch 1001-1064 "
                                        r"ckt 'BL': duplicate branch"):
        read_raw(path)


def test_9b3g_ends_before_facts(gridpack_data):
    path = gridpack_data / "raw" / "9b3g.raw"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing skipped
        case = read_raw(path)
    assert case.notes == (f"{path}:41: the file ends before the facts data; the sections "
                          "from there on (facts) hold no more records",)
    result = solve(case)
    assert np.abs(result.vm - case.buses.vm).max() < VM_TOL_STORED
