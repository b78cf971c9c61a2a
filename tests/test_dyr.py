"""Tests for the PSS/E DYR reader (jaxgrid.io.dyr).

Expected record counts were made by hand (grep of the quoted model names on
non-comment lines, cross-checked against the number of '/' terminators).
"""
from __future__ import annotations

import functools
import re
from pathlib import Path

import pytest

from conftest import SHARED_CASES, andes_cases_dir
from jaxgrid.io.dyr import DyrError, DyrWarning, read_dyr
from jaxgrid.records import DyrData

CASES = SHARED_CASES

EXPECTED_COUNTS = {
    "ieee39/IEEE39bus_3AC.dyr": {
        "GENROU": 9, "GENCLS": 1, "IEEET1": 8, "GAST": 1, "IEESGO": 2, "IEEEG1": 3,
        "TGOV1": 2, "ACMTBLU1": 3,
    },
    "ieee39/IEEE39bus_3AC_exdc1_gridpack.dyr": {
        "GENSAL": 11, "EXDC1": 9, "WSIEG1": 9, "GENCLS": 1, "ACMTBLU1": 3,
    },
    "ieee300/IEEE300_genrou_exdc1_tgov1_zone1ac.dyr": {
        "GENROU": 69, "EXDC1": 63, "TGOV1": 54, "ACMTBLU1": 34,
    },
    "ieee300/IEEE300_dyn_cmld_zone1.dyr": {
        "GENROU": 69, "IEEET1": 61, "TGOV1": 53, "CMLDBLU2": 47,
    },
    "ieee300/IEEE300_dyn_v2.dyr": {"GENROU": 69, "IEEET1": 63, "TGOV1": 54},
}
_ACTIVSG_MACHINES = {
    "GENROU": 410, "GENSAL": 25, "IEEET1": 289, "EXAC1": 6, "EXAC2": 38, "EXPIC1": 61,
    "ESAC1A": 4, "ESAC6A": 7, "ESDC1A": 12, "ESDC2A": 1, "SCRX": 5, "IEEEST": 434,
    "GGOV1": 367, "HYGOV": 25, "IEEEG1": 31,
}
EXPECTED_COUNTS["activsg2000/ACTIVSg2000_dyn_acmotor_zone3_v1.dyr"] = {
    **_ACTIVSG_MACHINES, "ACMTBLU1": 1125,
}
EXPECTED_COUNTS["activsg2000/ACTIVSg2000_dyn_cmld_zone3_v1.dyr"] = {
    **_ACTIVSG_MACHINES, "CMLDBLU2": 71,
}

# DYR files bundled with ANDES. Four of them end with ANDES-only disturbance
# records ("Line 'Toggle' Line_1 1.0 /"), which are not PSS/E data.
ANDES_COUNTS = {
    "ieee14/ieee14.dyr": {
        "GENROU": 5, "ESST3A": 4, "EXST1": 1, "IEEEG1": 2, "IEEEST": 1, "ST2CUT": 2, "TGOV1": 3,
    },
    "ieee14/ieee14_ieeevc.dyr": {
        "GENROU": 5, "ESST3A": 4, "EXST1": 1, "IEEEG1": 2, "IEEEST": 1, "ST2CUT": 2, "TGOV1": 3,
        "IEEEVC": 1,
    },
    "kundur/kundur_full.dyr": {"GENROU": 4, "EXDC2": 4, "TGOV1": 4},
    "kundur/kundur_gencls.dyr": {"GENCLS": 4},
    "nordic44/N44_BC.dyr": {
        "GENROU": 30, "GENSAL": 50, "HYGOV": 50, "IEEET2": 12, "IEESGO": 30, "SCRX": 54,
        "SEXS": 14, "STAB2A": 53,
    },
    "npcc/npcc_full.dyr": {"GENCLS": 21, "GENROU": 27, "IEEEX1": 24, "TGOV1": 29},
    "wecc/wecc_full.dyr": {
        "GENROU": 29, "ESDC2A": 8, "ESST3A": 4, "EXST1": 17, "IEEEG1": 29, "IEEEST": 4,
        "ST2CUT": 25,
    },
    "wecc/wecc_gencls.dyr": {"GENCLS": 29},
}

ACMOTOR = "activsg2000/ACTIVSg2000_dyn_acmotor_zone3_v1.dyr"


def _case(relative: str) -> Path:
    path = CASES / relative
    assert path.is_file(), f"reference case {path} not found (../shared/cases beside the repo)"
    return path


@functools.cache
def _parsed(relative: str) -> DyrData:
    return read_dyr(_case(relative))


def _andes_cases() -> Path:
    return andes_cases_dir()


def _write(tmp_path: Path, text: str, name: str = "bad.dyr") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# --- reference files -------------------------------------------------------------------


@pytest.mark.parametrize("relative", sorted(EXPECTED_COUNTS))
def test_reference_counts(relative):
    data = _parsed(relative)
    assert data.counts() == EXPECTED_COUNTS[relative]
    assert len(data.records) == sum(EXPECTED_COUNTS[relative].values())
    assert data.unsupported == {}
    assert all(r.source == str(CASES / relative) for r in data.records)


@pytest.mark.parametrize("relative", sorted(EXPECTED_COUNTS))
def test_genrou_has_14_cons(relative):
    for record in _parsed(relative).by_model("GENROU"):
        assert len(record.cons) == 14
        assert record.icons == () and record.header == ()
        assert record.record_type == "GENROU"


def test_ieee39_first_genrou_values():
    # File starts with a UTF-8 BOM and an empty line; the record is on lines 2-4.
    first = _parsed("ieee39/IEEE39bus_3AC.dyr").records[0]
    assert (first.model, first.bus, first.device_id, first.line) == ("GENROU", 30, "1", 2)
    assert first.cons[0] == 3.797  # T'do
    assert first.cons[1] == pytest.approx(0.033)  # T''do written 0.33000E-01
    assert first.cons[4] == 5.8  # H
    assert first.cons[13] == 0.4881  # S(1.2), glued to the '/'


def test_ieee39_trailing_comment_and_commented_records():
    data = _parsed("ieee39/IEEE39bus_3AC.dyr")
    (gencls,) = data.by_model("gencls")
    # "39 'GENCLS' 1  500.00  10.000/ CONSTANT INTERNAL VOLTAGE GENERATOR MODEL"
    assert (gencls.bus, gencls.line, gencls.cons) == (39, 101, (500.0, 10.0))
    assert 31 not in {r.bus for r in data.by_model("IEEET1")}  # commented out
    assert [r.bus for r in data.by_model("ACMTBLU1")] == [504, 507, 518]  # 508 commented out


@pytest.mark.parametrize("relative", [
    "ieee39/IEEE39bus_3AC.dyr",
    "ieee39/IEEE39bus_3AC_exdc1_gridpack.dyr",
    "ieee300/IEEE300_genrou_exdc1_tgov1_zone1ac.dyr",
    ACMOTOR,
])
def test_acmtblu1_layout(relative):
    for record in _parsed(relative).by_model("ACMTBLU1"):
        assert record.record_type == "USRLOD"
        assert record.header == (12, 1, 0, 35, 9, 29, 16)
        assert record.icons == ()
        assert len(record.cons) == 35
        assert record.cons[0] == 0.033  # Tstall
        assert record.cons[-1] == 5.0  # last CON


def test_acmtblu1_ids():
    assert {r.device_id for r in _parsed("ieee39/IEEE39bus_3AC.dyr").by_model("ACMTBLU1")} == {"2"}
    gridpack = _parsed("ieee39/IEEE39bus_3AC_exdc1_gridpack.dyr").by_model("ACMTBLU1")
    assert {r.device_id for r in gridpack} == {"1"}


@pytest.mark.parametrize("relative", [
    "ieee300/IEEE300_dyn_cmld_zone1.dyr",
    "activsg2000/ACTIVSg2000_dyn_cmld_zone3_v1.dyr",
])
def test_cmldblu2_layout(relative):
    for record in _parsed(relative).by_model("CMLDBLU2"):
        assert record.record_type == "USRLOD"
        assert record.header == (12, 1, 2, 133, 27, 146, 48)
        assert record.icons == (0, 0)
        assert len(record.cons) == 133


def test_cmldblu2_values():
    first = _parsed("ieee300/IEEE300_dyn_cmld_zone1.dyr").by_model("CMLDBLU2")[0]
    assert (first.bus, first.device_id, first.line) == (1, "1", 505)
    assert first.cons[0] == -1.25  # MVA < 0
    assert first.cons[51] == 99999.0  # written "99999." (motor A block, 15th value)
    assert first.cons[-2:] == (9999.0, 1.0)


def test_supported_none_accepts_everything():
    assert _parsed(ACMOTOR).unsupported == {}


def _activsg_supported() -> set[str]:
    return set(EXPECTED_COUNTS[ACMOTOR]) - {"GGOV1", "IEEEST"}


UNSUPPORTED_MESSAGE = ("2 unsupported dynamic models: GGOV1 x367 (first at line 4), "
                       "IEEEST x434 (first at line 5)")


def test_strict_unsupported_raises_one_error():
    path = _case(ACMOTOR)
    with pytest.raises(DyrError) as info:
        read_dyr(path, supported=_activsg_supported())
    assert str(info.value) == f"{path}: {UNSUPPORTED_MESSAGE}"


def test_lenient_unsupported_warns_and_keeps_records():
    path = _case(ACMOTOR)
    with pytest.warns(DyrWarning) as caught:
        data = read_dyr(path, supported=_activsg_supported(), strict=False)
    assert [str(w.message) for w in caught] == [f"{path}: {UNSUPPORTED_MESSAGE}"]
    assert data.unsupported == {"GGOV1": 367, "IEEEST": 434}
    assert data.counts() == EXPECTED_COUNTS[ACMOTOR]


def test_supported_names_are_case_insensitive():
    path = _case("ieee300/IEEE300_dyn_v2.dyr")
    assert read_dyr(path, supported={"genrou", "ieeet1", "TGOV1"}).unsupported == {}


# --- ANDES files -----------------------------------------------------------------------


@pytest.mark.parametrize("relative", sorted(ANDES_COUNTS))
def test_andes_counts(relative, tmp_path):
    text = (_andes_cases() / relative).read_text()
    psse_only = "\n".join(line for line in text.splitlines() if "'Toggle'" not in line)
    data = read_dyr(_write(tmp_path, psse_only, Path(relative).name))
    assert data.counts() == ANDES_COUNTS[relative]


def test_andes_toggle_record_is_rejected():
    path = _andes_cases() / "ieee14" / "ieee14.dyr"
    message = re.escape(f"{path}:69: ") + ".*IBUS = 'Line' is not an integer"
    with pytest.raises(DyrError, match=message):
        read_dyr(path)


# --- syntax -----------------------------------------------------------------------------


def test_free_format_syntax(tmp_path):
    text = (
        "\ufeff// header comment 'with quote\n"
        "1, 'genrou', '1 ', 5., -.5, 0.1D+01,\n"
        "   .25E-01  1e2 / 2 \"GENCLS\" 2 3.0 0 / 3 'GENCLS' 3 1 0 /\n"
        "   // 4 'GENCLS' 1 1 0 /\n"
        "4 'GENCLS' 1 1 0 / trailing text, ignored\n"
    )
    path = tmp_path / "free.dyr"
    path.write_bytes(text.encode("utf-8") + b"// latin-1 byte \xe9\n")
    data = read_dyr(path)
    assert [(r.model, r.bus, r.device_id, r.line) for r in data.records] == [
        ("GENROU", 1, "1", 2), ("GENCLS", 2, "2", 3), ("GENCLS", 3, "3", 3), ("GENCLS", 4, "1", 5),
    ]
    assert data.records[0].cons == (5.0, -0.5, 1.0, 0.025, 100.0)
    assert data.counts() == {"GENROU": 1, "GENCLS": 3}


def test_usrmdl_has_six_header_integers(tmp_path):
    path = _write(tmp_path, "7 'USRMDL' 1 'DEMOU1' 101 1 2 3 4 5\n 10 0\n 0.5 1.5 2.5 /\n")
    (record,) = read_dyr(path).records
    assert (record.model, record.record_type) == ("DEMOU1", "USRMDL")
    assert (record.header, record.icons, record.cons) == ((101, 1, 2, 3, 4, 5), (10, 0),
                                                          (0.5, 1.5, 2.5))


# --- errors -----------------------------------------------------------------------------


def test_usrlod_count_mismatch(tmp_path):
    cons = " ".join(["0.5"] * 34)  # header says 35
    path = _write(tmp_path, f"// comment\n504 'USRLOD' 2 'ACMTBLU1' 12 1 0 35 9 29 16\n {cons} /\n")
    message = (f"{path}:2: ACMTBLU1 (USRLOD) at bus 504 id '2': header says 7+NI+NC = 7+0+35 "
               "= 42 values after the model name, found 41")
    with pytest.raises(DyrError, match=re.escape(message)):
        read_dyr(path)


def test_non_numeric_con(tmp_path):
    path = _write(tmp_path, "30 'GENROU' 1 3.797 0.033 0.438 abc 5.8 /\n")
    message = f"{path}:1: GENROU at bus 30 id '1': CON(4) = 'abc' is not a number"
    with pytest.raises(DyrError, match=re.escape(message)):
        read_dyr(path)


def test_non_numeric_con_reports_its_own_line(tmp_path):
    path = _write(tmp_path, "30 'GENROU' 1 3.797 0.033\n 0.438 nan /\n")
    with pytest.raises(DyrError, match=re.escape(f"{path}:2: GENROU at bus 30 id '1': CON(4)")):
        read_dyr(path)


@pytest.mark.parametrize(("text", "line", "fragment"), [
    ("1 'GENCLS' 1 3 0 /\n2 'GENCLS' 1 3 0\n", 2, "record not terminated by '/'"),
    ("1 'GENCLS' 1 3,, 0 /\n", 1, "empty field between commas"),
    ("1 'GENCLS /\n", 1, "unterminated quote"),
    ("1 'GENCLS' /\n", 1, "record has 2 fields"),
    ("1 'USRLOD' 2 'ACMTBLU1' 12 1 0.5 0 9 29 16 /\n", 1, "NI = '0.5' is not an integer"),
    ("1 'USRLOD' 2 'ACMTBLU1' 12 1 /\n", 1, "7 header integers expected"),
    ("1 'USRBUS' 'X' 504 0 0 0 0 0 /\n", 1, "user record type USRBUS at bus 1: layout not known"),
])
def test_malformed_records(tmp_path, text, line, fragment):
    path = _write(tmp_path, text)
    with pytest.raises(DyrError, match=re.escape(f"{path}:{line}: ") + ".*" + re.escape(fragment)):
        read_dyr(path)
