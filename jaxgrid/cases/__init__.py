"""Built-in cases: `jaxgrid.cases.load(name, **params) -> Case`.

Every built-in case is built by this package's own code from public data
(MATPOWER case files as shipped by PYPOWER); nothing is read from the PNNL
reference files. Builders register themselves with `register`, so the FIDVR
study variants (dynamic data, motor loads, operating points) slot in beside
the network-only cases.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable

from jaxgrid.case import Case


@dataclasses.dataclass(frozen=True)
class CaseSpec:
    """A registered builder and what it builds."""

    name: str
    build: Callable[..., Case]
    description: str


_REGISTRY: dict[str, CaseSpec] = {}


def register(name: str, description: str) -> Callable[[Callable[..., Case]], Callable[..., Case]]:
    """Decorator: register `build(**params) -> Case` under `name`."""

    def decorate(build: Callable[..., Case]) -> Callable[..., Case]:
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


def load(name: str, **params) -> Case:
    """Build the registered case `name` (params go to its builder)."""
    return _spec(name).build(**params)


def _spec(name: str) -> CaseSpec:
    if name not in _REGISTRY:
        raise ValueError(f"unknown case {name!r}; built-in cases: {', '.join(names())}")
    return _REGISTRY[name]


from jaxgrid.cases import ieee  # noqa: E402,F401  (registers the IEEE cases)
