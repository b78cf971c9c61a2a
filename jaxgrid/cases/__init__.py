"""Built-in cases: `jaxgrid.cases.load(name, **params) -> Case | StudyCase`.

Every built-in case is built by this package's own code from public data
(MATPOWER case files as shipped by PYPOWER); nothing is read from the PNNL
reference files. Builders register themselves with `registry.register`: the network-only
cases (`ieee`) return a `Case`, the FIDVR study cases (`fidvr`: dynamic data,
motor loads, task buses, operating point) a `StudyCase`.
"""
from __future__ import annotations

from jaxgrid.case import Case
from jaxgrid.cases import fidvr, ieee  # noqa: F401  (importing them registers their cases)
from jaxgrid.cases.fidvr import StudyCase
from jaxgrid.cases.registry import names, spec

__all__ = ["StudyCase", "load", "names"]


def load(name: str, **params) -> Case | StudyCase:
    """Build the registered case `name` (params go to its builder)."""
    return spec(name).build(**params)
