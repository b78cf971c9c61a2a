"""Bad input gives a clear error: file, line, record, field and value in the message.

Covers the RAW reader (`jaxgrid.io.raw`), case validation (`jaxgrid.case`) and
the power flow (`jaxgrid.powerflow`). Errors in the real IEEE 39-bus file are
made by editing its text in memory and writing the result to `tmp_path` (the
shared file is only read); small systems are hand-written PSS/E v33 text.
Every broken input has a control: the unbroken text parses (or solves).
"""
from __future__ import annotations

import dataclasses
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from conftest import SHARED_CASES, raw_v33
from jaxgrid.case import CaseError
from jaxgrid.io.raw import RawWarning, parse_raw, read_raw
from jaxgrid.powerflow import PowerFlowError, PowerFlowOptions, solve

IEEE39 = SHARED_CASES / "ieee39" / "IEEE39bus_multiloads_xfmr4_smallX_v30.raw"


# --------------------------------------------------------------------------- #
# Helpers
# --------------------------------------------------------------------------- #

def ieee39_lines() -> list[str]:
    """Lines of the shared IEEE 39-bus v30 file (read in place, never copied)."""
    return IEEE39.read_text(encoding="utf-8").splitlines()


def line_number(lines: list[str], pattern: str) -> int:
    """1-based number of the only line matching regex `pattern` (at its start)."""
    hits = [k + 1 for k, text in enumerate(lines) if re.match(pattern, text)]
    assert len(hits) == 1, f"{pattern!r} matched lines {hits}"
    return hits[0]


def set_field(lines: list[str], number: int, index: int, value: str) -> list[str]:
    """Copy of `lines` with comma-separated field `index` of line `number` replaced."""
    fields = lines[number - 1].split(",")
    fields[index] = value
    out = list(lines)
    out[number - 1] = ",".join(fields)
    return out


def write(tmp_path: Path, lines: list[str], name: str = "case.raw") -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def read_quietly(path: Path):
    """read_raw without the RawWarning the 39-bus file gives (skipped tap control)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RawWarning)
        return read_raw(path)


# Bus: I,'NAME',BASKV,IDE,AREA,ZONE,OWNER,VM,VA
# Generator: I,'ID',PG,QG,QT,QB,VS,IREG,MBASE,ZR,ZX,RT,XT,GTAP,STAT,RMPCT,PT,PB
# Branch: I,J,'CKT',R,X,B,RATEA,RATEB,RATEC,GI,BI,GJ,BJ,ST
# Load: I,'ID',STATUS,AREA,ZONE,PL,QL,IP,IQ,YP,YQ,OWNER
SLACK_GEN = "1,'1', 0.0, 0.0, 9999.0, -9999.0, 1.00, 0, 100.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1, 100.0, 9999.0, -9999.0\n"

FOUR_BUS = """\
1,'SLACK', 230.0, 3, 1, 1, 1, 1.00, 0.0
2,'MID',   230.0, 1, 1, 1, 1, 1.00, 0.0
3,'END',   230.0, 1, 1, 1, 1, 1.00, 0.0
4,'STUB',  230.0, 1, 1, 1, 1, 1.00, 0.0
"""


def four_bus_branches(status_3_4: int) -> str:
    return (
        "1, 2,'1', 0.01, 0.10, 0.02, 0, 0, 0, 0, 0, 0, 0, 1\n"
        "2, 3,'1', 0.01, 0.10, 0.02, 0, 0, 0, 0, 0, 0, 0, 1\n"
        f"3, 4,'1', 0.01, 0.10, 0.02, 0, 0, 0, 0, 0, 0, 0, {status_3_4}\n")


def two_bus(load_mw: float) -> str:
    """Slack bus 1 feeding a constant-power load at bus 2 over X = 0.5 p.u."""
    return raw_v33(
        buses="1,'SOURCE', 230.0, 3, 1, 1, 1, 1.00, 0.0\n"
              "2,'SINK',   230.0, 1, 1, 1, 1, 1.00, 0.0\n",
        loads=f"2,'1', 1, 1, 1, {load_mw}, 0.0, 0.0, 0.0, 0.0, 0.0, 1\n",
        generators=SLACK_GEN,
        branches="1, 2,'1', 0.0, 0.5, 0.0, 0, 0, 0, 0, 0, 0, 0, 1\n")


# --------------------------------------------------------------------------- #
# The unmodified 39-bus file (control for the edits below)
# --------------------------------------------------------------------------- #

def test_ieee39_unmodified_reads(tmp_path):
    """Control: the unedited 39-bus text, written to tmp_path, reads without error."""
    lines = ieee39_lines()
    case = read_quietly(write(tmp_path, lines))
    assert case.n_bus == 43
    # The branch and load records the tests below edit are where they expect them.
    assert line_number(lines, r"\s*1,\s*2,'1 '") == 88
    assert line_number(lines, r"\s*3,'1 ',1,") == 48
    assert line_number(lines, r"\s*31,' GBUS31") == 34
    assert 88 in case.branches.line.tolist()


# --------------------------------------------------------------------------- #
# 1. Truncated file
# --------------------------------------------------------------------------- #

def test_truncated_in_branch_section(tmp_path):
    """A file cut in the middle of the branch section: end of file in branch data."""
    lines = ieee39_lines()
    first_branch = line_number(lines, r"\s*1,\s*2,'1 '")
    keep = first_branch + 10  # 11 branch records, no closing '0' line
    path = write(tmp_path, lines[:keep], "cut_branch.raw")
    with pytest.raises(CaseError) as excinfo:
        read_raw(path)
    message = str(excinfo.value)
    assert message.startswith(f"{path}:{keep}: ")
    assert "unexpected end of file in branch data" in message
    assert "closing '0' line is missing" in message
    assert excinfo.value.source == str(path) and excinfo.value.line == keep


def test_truncated_inside_transformer_record(tmp_path):
    """A file cut inside a 4-line transformer record: end of file names that transformer."""
    lines = ieee39_lines()
    start = line_number(lines, r"\s*2,\s*30,\s*0,'1 '")  # first transformer record
    keep = start + 2  # record line, impedance line, winding-1 line; winding 2 missing
    path = write(tmp_path, lines[:keep], "cut_transformer.raw")
    with pytest.raises(CaseError) as excinfo:
        read_raw(path)
    expected = (f"{path}:{keep}: unexpected end of file in transformer 2-30 ckt '1' "
                f"(record starting at line {start})")
    assert str(excinfo.value) == expected


def test_truncated_between_sections(tmp_path):
    """A file that stops after the branch section's '0' line: transformer data missing."""
    lines = ieee39_lines()
    end_of_branches = line_number(lines, r"\s*0\s*/End of Branch data")
    path = write(tmp_path, lines[:end_of_branches], "cut_section.raw")
    with pytest.raises(CaseError, match=re.escape(
            f"{path}:{end_of_branches}: unexpected end of file before transformer data")):
        read_raw(path)


# --------------------------------------------------------------------------- #
# 2. Non-numeric field
# --------------------------------------------------------------------------- #

def test_branch_reactance_not_a_number(tmp_path):
    """X of branch 1-2 replaced by 'abc': file, line, branch, field and text in the message."""
    lines = ieee39_lines()
    number = line_number(lines, r"\s*1,\s*2,'1 '")
    bad = set_field(lines, number, 4, "abc")  # I, J, CKT, R, X
    assert bad[number - 1].split(",")[3].strip() == "0.00350"  # R untouched
    path = write(tmp_path, bad, "bad_x.raw")
    with pytest.raises(CaseError) as excinfo:
        read_raw(path)
    assert str(excinfo.value) == f"{path}:{number}: branch 1-2 ckt '1': X = 'abc' is not a number"
    assert excinfo.value.line == number == 88


def test_load_power_not_a_number(tmp_path):
    """PL of the load at bus 3 replaced by 'abc': message names the load record and PL."""
    lines = ieee39_lines()
    number = line_number(lines, r"\s*3,'1 ',1,")
    bad = set_field(lines, number, 5, "abc")  # I, ID, STATUS, AREA, ZONE, PL
    path = write(tmp_path, bad, "bad_pl.raw")
    with pytest.raises(CaseError) as excinfo:
        read_raw(path)
    assert str(excinfo.value) == (
        f"{path}:{number}: load at bus 3 id '1': PL = 'abc' is not a number")


# --------------------------------------------------------------------------- #
# 3.-5. Case validation errors
# --------------------------------------------------------------------------- #

def _missing_to_bus_error(tmp_path) -> tuple[str, Path, int]:
    lines = ieee39_lines()
    number = line_number(lines, r"\s*1,\s*2,'1 '")
    path = write(tmp_path, set_field(lines, number, 1, "  99999"), "missing_bus.raw")
    with pytest.raises(CaseError) as excinfo:
        read_quietly(path)
    return str(excinfo.value), path, number


def test_branch_to_missing_bus(tmp_path):
    """Branch 1-2 re-pointed to bus 99999: names the line, the branch (external numbers) and
    the missing bus."""
    message, path, number = _missing_to_bus_error(tmp_path)
    assert message == f"{path}:{number}: branch 1-99999 ckt '1': to bus 99999 does not exist"


def test_branch_from_missing_bus(tmp_path):
    """Branch 1-2 with its from-bus changed to 99999: 'from bus 99999 does not exist'."""
    lines = ieee39_lines()
    number = line_number(lines, r"\s*1,\s*2,'1 '")
    path = write(tmp_path, set_field(lines, number, 0, "99999"), "missing_from.raw")
    with pytest.raises(CaseError) as excinfo:
        read_quietly(path)
    assert str(excinfo.value) == (
        f"{path}:{number}: branch 99999-2 ckt '1': from bus 99999 does not exist")


def test_zero_impedance_branch(tmp_path):
    """Branch 1-2 with R = X = 0: names the line, the branch and X = 0."""
    lines = ieee39_lines()
    number = line_number(lines, r"\s*1,\s*2,'1 '")
    bad = set_field(set_field(lines, number, 3, " 0.0"), number, 4, " 0.0")
    path = write(tmp_path, bad, "zero_z.raw")
    with pytest.raises(CaseError) as excinfo:
        read_quietly(path)
    message = str(excinfo.value)
    assert message.startswith(f"{path}:{number}: branch 1-2 ckt '1': X = 0, R = 0: ")
    assert "zero or non-finite series impedance is not supported" in message


def test_no_slack_bus(tmp_path):
    """The only type-3 bus (31) changed to type 2: 'no slack bus' with the file name."""
    lines = ieee39_lines()
    number = line_number(lines, r"\s*31,' GBUS31")
    assert lines[number - 1].split(",")[3] == "3"
    path = write(tmp_path, set_field(lines, number, 3, "2"), "no_slack.raw")
    with pytest.raises(CaseError) as excinfo:
        read_quietly(path)
    assert str(excinfo.value) == f"{path}: no slack bus (a bus of type 3) in the case"


# --------------------------------------------------------------------------- #
# 6. Islanded bus
# --------------------------------------------------------------------------- #

def test_islanded_bus():
    """Bus 4 whose only branch is out of service: CaseError naming bus 4 and 'islanded'."""
    good = raw_v33(FOUR_BUS, generators=SLACK_GEN, branches=four_bus_branches(1))
    case = parse_raw(good, "four.raw")  # control: connected, parses
    assert case.n_bus == 4 and case.branches.in_service.all()

    text = raw_v33(FOUR_BUS, generators=SLACK_GEN, branches=four_bus_branches(0))
    bus4_line = line_number(text.splitlines(), r"4,'STUB'")
    with pytest.raises(CaseError) as excinfo:
        parse_raw(text, "island.raw")
    assert str(excinfo.value) == (
        f"island.raw:{bus4_line}: bus 4: islanded, no in-service path to a slack bus "
        "(buses [4]); mark them type 4 or connect them")

    # The advice in the message works: bus 4 marked isolated (type 4) is accepted.
    fixed = text.replace("4,'STUB',  230.0, 1,", "4,'STUB',  230.0, 4,")
    assert fixed != text
    assert parse_raw(fixed, "island.raw").buses.kind.tolist() == [3, 1, 1, 4]


# --------------------------------------------------------------------------- #
# 7. Unsupported version
# --------------------------------------------------------------------------- #

def test_unsupported_raw_version():
    """REV = 36 in the first line: CaseError at line 1 listing the supported versions."""
    good = raw_v33(FOUR_BUS, generators=SLACK_GEN, branches=four_bus_branches(1))
    text = good.replace("0, 100.00, 33,", "0, 100.00, 36,", 1)
    assert text != good
    with pytest.raises(CaseError) as excinfo:
        parse_raw(text, "rev36.raw")
    assert str(excinfo.value) == (
        "rev36.raw:1: case identification: REV = 36: RAW version not supported "
        "(supported: 23, 30, 31, 32, 33, 34, 35)")


# --------------------------------------------------------------------------- #
# 8. Unsolvable case
# --------------------------------------------------------------------------- #

def test_power_flow_does_not_converge():
    """50 p.u. load over X = 0.5 (limit ~2 p.u.): PowerFlowError with the worst bus, no NaNs."""
    light = parse_raw(two_bus(50.0), "two_bus_light.raw")  # control: 0.5 p.u. solves
    result = solve(light)
    assert np.all(np.isfinite(result.vm)) and result.max_mismatch < 1e-8

    heavy = parse_raw(two_bus(5000.0), "two_bus_heavy.raw")
    assert heavy.loads.p_power.tolist() == [50.0]
    outcome = None
    with pytest.raises(PowerFlowError) as excinfo:
        outcome = solve(heavy, PowerFlowOptions())
    assert outcome is None  # raised, nothing (no NaN voltages) handed back
    message = str(excinfo.value)
    found = re.fullmatch(
        r"two_bus_heavy\.raw: power flow did not converge in (\d+) iterations: "
        r"largest mismatch (\S+) p\.u\. \((P|Q)\) at bus (\d+)", message)
    assert found, message
    mismatch = float(found.group(2))
    assert math.isfinite(mismatch) and mismatch > 1e-8
    assert int(found.group(4)) == 2  # the load bus; the slack bus has no P/Q rows
    assert "nan" not in message.lower()


# --------------------------------------------------------------------------- #
# 9. Skipped records are warned about
# --------------------------------------------------------------------------- #

# Two-terminal DC (v33, 3 lines): 'NAME',MDC,RDC,SETVL,VSCHD,... / rectifier / inverter.
DC_LINES = """\
'DC 1', 1, 8.0, 100.0, 500.0, 0.0, 0.0, 0.0, I, 0.0, 20, 1.0
1, 2, 20.0, 5.0, 0.0, 5.0, 230.0, 1.0, 1.0, 1.5, 0.5, 0.00625, 0, 0, 0, '1', 0.0
3, 2, 20.0, 15.0, 0.0, 5.0, 230.0, 1.0, 1.0, 1.5, 0.5, 0.00625, 0, 0, 0, '1', 0.0
'DC 2', 1, 8.0, 100.0, 500.0, 0.0, 0.0, 0.0, I, 0.0, 20, 1.0
2, 2, 20.0, 5.0, 0.0, 5.0, 230.0, 1.0, 1.0, 1.5, 0.5, 0.00625, 0, 0, 0, '1', 0.0
3, 2, 20.0, 15.0, 0.0, 5.0, 230.0, 1.0, 1.0, 1.5, 0.5, 0.00625, 0, 0, 0, '1', 0.0
"""
# FACTS (v33, 1 line): 'NAME',I,J,MODE,PDES,QDES,VSET,SHMX,TRMX,VTMN,VTMX,VSMX,IMX,LINX,...
FACTS = "'SVC 1', 2, 0, 1, 0.0, 0.0, 1.0, 100.0, 9999.0, 0.9, 1.1, 1.0, 0.0, 0.05, 100.0, 1\n"

THREE_BUS = "".join(FOUR_BUS.splitlines(keepends=True)[:3])
THREE_BUS_BRANCHES = "".join(four_bus_branches(1).splitlines(keepends=True)[:2])


def test_skipped_records_are_warned_and_counted():
    """Two DC lines and a FACTS device: one RawWarning naming sections and counts."""
    plain = raw_v33(THREE_BUS, generators=SLACK_GEN, branches=THREE_BUS_BRANCHES)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RawWarning)  # control: nothing skipped, no warning
        case = parse_raw(plain, "plain.raw")
    assert case.skipped == {}

    text = raw_v33(THREE_BUS, generators=SLACK_GEN, branches=THREE_BUS_BRANCHES,
                   two_terminal_dc=DC_LINES, facts=FACTS)
    with pytest.warns(RawWarning) as record:
        case = parse_raw(text, "hvdc.raw")
    messages = [str(w.message) for w in record if issubclass(w.category, RawWarning)]
    assert messages == ["hvdc.raw: records not modelled, skipped: two-terminal dc x2, facts x1"]
    assert case.skipped == {"two-terminal dc": 2, "facts": 1}
    # The 3-line DC records were consumed whole: the rest of the case is intact.
    assert case.n_bus == 3 and len(case.branches.r) == 2 and len(case.generators.bus) == 1


# --------------------------------------------------------------------------- #
# Issue 28: duplicate identities, implausible values, no bare exceptions
# --------------------------------------------------------------------------- #

def repeat_line(lines: list[str], number: int, count: int = 1) -> list[str]:
    """Copy of `lines` with lines number .. number + count - 1 written twice."""
    return lines[:number + count - 1] + lines[number - 1:number + count - 1] + lines[
        number + count - 1:]


@pytest.mark.parametrize("pattern, count, record", [
    (r"\s*30,'1',", 1, r"generator at bus 30 id '1': duplicate generator"),
    (r"\s*24,'1 ',1,", 1, r"load at bus 24 id '1': duplicate load"),
    (r"\s*1,\s*2,'1 '", 1, r"branch 1-2 ckt '1': duplicate branch"),
    (r"\s*2,\s*30,\s*0,'1 '", 4, r"transformer 2-30 ckt '1': duplicate transformer"),
])
def test_duplicate_record_identity(tmp_path, pattern, count, record):
    """A record repeated (same bus and ID, or same buses and circuit) is rejected, as PSS/E
    does, at the repeat's line, naming the first one."""
    lines = ieee39_lines()
    first = line_number(lines, pattern)
    path = write(tmp_path, repeat_line(lines, first, count))
    with pytest.raises(CaseError, match=rf"^{re.escape(str(path))}:{first + count}: {record} "
                                        rf"\(.*line {first}\)"):
        read_quietly(path)


def test_duplicate_three_winding_transformer(tmp_path):
    """A 3-winding transformer record (5 lines) given twice is rejected at the repeat."""
    from conftest import andes_cases_dir

    lines = (andes_cases_dir() / "wscc9/wscc9_3wxfr.raw").read_text().splitlines()
    first = line_number(lines, r"\s*4,\s*5,\s*6,'1 '")
    path = write(tmp_path, repeat_line(lines, first, 5))
    with pytest.raises(CaseError, match=rf":{first + 5}: transformer 4-5-6 ckt '1': duplicate "
                                        rf"transformer \(first at line {first}\)"):
        read_quietly(path)


TRANSFORMER_2_30 = r"\s*2,\s*30,\s*0,'1 '"


@pytest.mark.parametrize("edit, message", [
    # (line pattern, offset from it, field index, value) -> error text after file:line:
    ((TRANSFORMER_2_30, 2, 0, "0.0"), r"transformer 2-30 ckt '1': WINDV1 gives an off-nominal "
                                      r"ratio of 0: must lie in \[0.1, 10\] p.u."),
    ((TRANSFORMER_2_30, 3, 0, "0.0"), r".*: WINDV2 gives an off-nominal ratio of 0"),
    ((TRANSFORMER_2_30, 2, 0, "1e-300"), r".*: WINDV1 gives an off-nominal ratio of 1e-300"),
    ((TRANSFORMER_2_30, 2, 0, "1e300"), r".*: WINDV1 = 1e300: must lie in \[-1e\+12, 1e\+12\]"),
    ((r"0,\s+100.00, 30", 0, 1, " 0.0"), r"case identification: SBASE = 0.0: must lie in "
                                         r"\(0, 1e\+06\] MVA"),
    ((r"0,\s+100.00, 30", 0, 2, " 1e400"), r"case identification: REV = '1e400' is not a number"),
    ((r"\s*24,' LBUS24", 0, 0, "1e20"), r"bus record: I = 1e20: must lie in \[1, 999999\]"),
    ((r"\s*24,' LBUS24", 0, 7, "1e20"), r"bus 24: ZONE = 1e20: must lie in \[-2.14748e\+09"),
    ((r"\s*24,' LBUS24", 0, 2, "-345.0"), r"bus 24: BASKV = -345.0: must lie in \[0, 10000\] kV"),
    ((r"\s*30,'1',", 0, 4, "-10000.0"), r"generator at bus 30 id '1': QT = -10000 Mvar < "
                                        r"QB = -9999 Mvar"),
    ((r"\s*30,'1',", 0, 6, "0.0"), r"generator at bus 30 id '1': VS = 0.0: must lie in "
                                   r"\(0, 2\) p.u."),
    # a section end marker made a record of a section that is skipped: its counts are fields
    ((r" 0 /End of Multi-terminal dc", 0, 0, "0.0"), r"multi-terminal dc record: NCONV = "
                                                    r"'Begin' is not a number"),
])
def test_implausible_raw_values(tmp_path, edit, message):
    """Values that used to raise a bare ZeroDivisionError/OverflowError, or were accepted and
    broke the power flow, give a CaseError with file:line: record: field."""
    pattern, offset, index, value = edit
    lines = ieee39_lines()
    number = line_number(lines, pattern) + offset
    path = write(tmp_path, set_field(lines, number, index, value))
    with pytest.raises(CaseError, match=rf"^{re.escape(str(path))}:{number}: {message}"):
        read_quietly(path)


def test_three_winding_ratio_zero(tmp_path):
    """WINDV = 0 in a 3-winding record: CaseError at the winding's line, no ZeroDivisionError."""
    from conftest import andes_cases_dir

    lines = (andes_cases_dir() / "wscc9/wscc9_3wxfr.raw").read_text().splitlines()
    number = line_number(lines, r"\s*4,\s*5,\s*6,'1 '") + 3  # winding 2
    path = write(tmp_path, set_field(lines, number, 0, "0.0"))
    with pytest.raises(CaseError, match=rf":{number}: transformer 4-5-6 ckt '1': WINDV2 gives "
                                        "an off-nominal ratio of 0"):
        read_quietly(path)


# --------------------------------------------------------------------------- #
# Issue 28: dynamic data (compile)
# --------------------------------------------------------------------------- #

SMIB_RAW = raw_v33(
    buses="1,'GEN', 230.0, 3, 1, 1, 1, 1.00, 0.0\n"
          "2,'LOAD', 230.0, 1, 1, 1, 1, 1.00, 0.0\n",
    loads="2,'1', 1, 1, 1, 50.0, 10.0, 0.0, 0.0, 0.0, 0.0, 1\n",
    generators="1,'1', 50.0, 10.0, 9999.0, -9999.0, 1.00, 0, 100.0, 0.0, 0.3, 0.0, 0.0, "
               "1.0, 1, 100.0, 9999.0, -9999.0\n",
    branches="1, 2,'1', 0.0, 0.1, 0.0, 0, 0, 0, 0, 0, 0, 0, 1\n")
IEEEG1_K8 = ("'IEEEG1' 1 0 0 20.0 0.0 0.0 0.1 0.1 -0.5 10.0 0.0 0.32 0.27 0.0 10.0 0.0 "
             "0.0 0.13 0.25 0.0 0.12 0.48 0.10 /")


def compile_smib(tmp_path, dyr_text: str, **options):
    """compile_model of the two-bus system (GENCLS at bus 1) with DYR text."""
    from jaxgrid.compile import CompileOptions, compile_model
    from jaxgrid.io.dyr import read_dyr

    raw = write(tmp_path, [SMIB_RAW], "smib.raw")
    dyr = tmp_path / "smib.dyr"
    dyr.write_text(dyr_text)
    return compile_model(read_raw(raw), read_dyr(dyr), CompileOptions(**options))


def test_dynamic_record_without_generator(tmp_path):
    """A governor on a generator the case does not have (wrong ID): strict raises ModelError
    naming file:line; lenient drops it with a ModelWarning and a line in GridModel.notes."""
    from jaxgrid.compile import ModelWarning
    from jaxgrid.models.base import ModelError

    text = "1 'GENCLS' 1 3.0 0.0 /\n1 " + IEEEG1_K8.replace("'IEEEG1' 1", "'IEEEG1' 2") + "\n"
    orphan = r"smib.dyr:2: IEEEG1 at bus 1 id '2'"
    with pytest.raises(ModelError, match=rf"1 dynamic record\(s\) name a generator .*{orphan}"):
        compile_smib(tmp_path, text)
    with pytest.warns(ModelWarning, match=orphan):
        model = compile_smib(tmp_path, text, strict=False)
    assert any(re.search(orphan, note) for note in model.notes), model.notes
    assert not model.governors


def test_model_notes_reach_the_report(tmp_path):
    """IEEEG1's dropped K2 + K4 + K6 + K8 is a ModelWarning and a GridModel.notes line that
    names the unit."""
    from jaxgrid.compile import ModelWarning

    with pytest.warns(ModelWarning, match=r"IEEEG1 at bus 1 id '1': K2 \+ K4 \+ K6 \+ K8 = 0.1"):
        model = compile_smib(tmp_path, "1 'GENCLS' 1 3.0 0.0 /\n1 " + IEEEG1_K8 + "\n")
    assert any("drive no machine" in note for note in model.notes), model.notes


@pytest.mark.parametrize("cons, field", [("1e300 0.0", "H"), ("3.0 1e300", "D")])
def test_float32_overflow_is_named(tmp_path, cons, field):
    """A CON within its range but beyond float32 is rejected at the precision cast, naming
    the device and the parameter; float64 takes it."""
    from jaxgrid.models.base import ModelError

    with pytest.raises(ModelError, match=rf"GENCLS at bus 1 id '1': {field} = 1e\+300: must be "
                                         r"finite with \|x\| <= 3.4e\+38"):
        compile_smib(tmp_path, f"1 'GENCLS' 1 {cons} /\n")


@pytest.mark.parametrize("h", [float("nan"), -3.0])
def test_invalid_parameter_set_through_the_api_diverges_at_t0(tmp_path, h):
    """A machine's H changed to NaN or < 0 after compiling is flagged as diverged at t = 0
    (not run as an infinite bus); the unchanged model is not."""
    from jaxgrid.simulate import simulate

    model = compile_smib(tmp_path, "1 'GENCLS' 1 3.0 0.0 /\n")
    group = model.machines[0]
    changed = dataclasses.replace(model, machines=(group.replace(params={
        **group.params, "h": np.full_like(group.params["h"], h)}),))
    control, bad = (simulate(m, 0.02, 0.005, decimation=2) for m in (model, changed))
    assert not bool(control.diverged)
    assert bool(bad.diverged) and float(bad.diverged_at) == 0.0
