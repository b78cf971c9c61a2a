"""Built-in cases: `jaxgrid.cases.load(name, **params) -> Case | StudyCase`.

Every built-in case is built by this package's own code from public data
(MATPOWER case files as shipped by PYPOWER); nothing is read from the PNNL
reference files. Builders register themselves with `register`: the network-only
cases (`ieee`) return a `Case`, the FIDVR study cases (`fidvr`: dynamic data,
motor loads, task buses, operating point) a `StudyCase`.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from jaxgrid.case import Case


@dataclasses.dataclass(frozen=True)
class CaseSpec:
    """A registered builder and what it builds."""

    name: str
    build: Callable[..., Any]
    description: str


_REGISTRY: dict[str, CaseSpec] = {}


def register(name: str, description: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorator: register `build(**params) -> Case | StudyCase` under `name`."""

    def decorate(build: Callable[..., Any]) -> Callable[..., Any]:
        if name in _REGISTRY:
            raise ValueError(f"case {name!r} is registered twice")
        _REGISTRY[name] = CaseSpec(name, build, description)
        return build

    return decorate


def names() -> tuple[str, ...]:
    """Registered case names."""
    return tuple(sorted(_REGISTRY))


def describe(name: str) -> str:
    """One-line description of a registered case."""
    return _spec(name).description


def load(name: str, **params) -> Case | StudyCase:
    """Build the registered case `name` (params go to its builder)."""
    return _spec(name).build(**params)


def _spec(name: str) -> CaseSpec:
    if name not in _REGISTRY:
        raise ValueError(f"unknown case {name!r}; built-in cases: {', '.join(names())}")
    return _REGISTRY[name]


from jaxgrid.cases import ieee  # noqa: E402,F401  (registers the IEEE cases)
from jaxgrid.cases import fidvr  # noqa: E402,F401  (registers the FIDVR study cases)
from jaxgrid.cases.fidvr import StudyCase  # noqa: E402
