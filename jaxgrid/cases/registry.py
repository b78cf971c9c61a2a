"""The registry of built-in cases: each builder registers itself under a name (`register`).

The builder modules (`jaxgrid.cases.ieee`, `jaxgrid.cases.fidvr`) import this module; the
package `jaxgrid.cases` imports them, so the registry is full once the package is imported.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any


@dataclasses.dataclass(frozen=True)
class CaseSpec:
    """A registered builder (its docstring says what it builds)."""

    name: str
    build: Callable[..., Any]


_REGISTRY: dict[str, CaseSpec] = {}


def register(name: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorator: register `build(**params) -> Case | StudyCase` under `name`."""

    def decorate(build: Callable[..., Any]) -> Callable[..., Any]:
        if name in _REGISTRY:
            raise ValueError(f"case {name!r} is registered twice")
        _REGISTRY[name] = CaseSpec(name, build)
        return build

    return decorate


def names() -> tuple[str, ...]:
    """Registered case names."""
    return tuple(sorted(_REGISTRY))


def spec(name: str) -> CaseSpec:
    """The registered builder `name`; ValueError naming the registered cases if none."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown case {name!r}; built-in cases: {', '.join(names())}")
    return _REGISTRY[name]
