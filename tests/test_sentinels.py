"""WECC/PSS/E sentinel values (999, 9999) read through the CON declarations
(`jaxgrid.models.base.Sentinel`): docs/models.md's table is the declarations, a sentinel is
accepted wherever it is declared, anything else outside a range stays an error. Reading and
behaviour on whole models: tests/test_acmotor.py, tests/test_cmld.py (`*sentinel*`).
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from jaxgrid.models.acmotor import Acmtblu1
from jaxgrid.models.base import SENTINELS
from jaxgrid.models.cmld import Cmldblu2
from jaxgrid.models.cmld_cons import MOTOR_D_CONS, MOTORS
from jaxgrid.models.stabilizers import Ieeest

DOCS = Path(__file__).resolve().parents[1] / "docs" / "models.md"
ROWS = {"ACMTBLU1, CMLD motor D": Acmtblu1.cons,
        "CMLDBLU1/2 motors A, B, C": tuple(c for c in Cmldblu2.cons if c not in MOTOR_D_CONS),
        "IEEEST": Ieeest.cons}


def docs_table() -> dict[str, set[str]]:
    """{model column: CON names} of the table under '## Sentinel values', with the motor
    suffix x expanded to A, B, C; asserts its sentinel column lists SENTINELS."""
    text = DOCS.read_text().split("## Sentinel values", 1)[1].split("\n## ", 1)[0]
    out: dict[str, set[str]] = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not line.startswith("| ") or cells[0] in ("model", "---"):
            continue
        values = [float(v) for v in re.findall(r"\d+", cells[2])]
        assert values == list(SENTINELS), f"docs row {cells}: sentinels {values}"
        names = {n.strip() for n in cells[1].split(",")}
        names = {n[:-1] + m.upper() if n.endswith("x") else n for n in names for m in MOTORS}
        out.setdefault(cells[0], set()).update(names)
    return out


def test_docs_table_is_the_declarations():
    declared = {row: {c.name.upper() for c in cons if c.sentinel} for row, cons in ROWS.items()}
    assert docs_table() == declared


@pytest.mark.parametrize("con", [c for cons in ROWS.values() for c in cons if c.sentinel],
                         ids=lambda c: c.name)
def test_declared_sentinels_pass_the_range_check_and_nothing_else_does(con):
    """Every declared CON accepts 999 and 9999 (their negatives for a lower limit; a note only
    where they lie outside its range); a value outside its range that is no sentinel still
    fails with the range."""
    for value in con.sentinel.values:
        assert con.check(value) is None, f"{con.name} = {value:g}"
        outside = not con.lo <= value <= con.hi
        assert (con.sentinel_meaning(value) == con.sentinel.meaning) == outside
    not_a_sentinel = con.lo - 1 if con.sentinel.lower else 10 * con.hi + 1
    assert con.check(not_a_sentinel) == f"must lie in [{con.lo}, {con.hi}]"
