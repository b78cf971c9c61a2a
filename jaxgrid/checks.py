"""One rule for the numbers a user writes: finite and inside a stated range, with a unit.

Every reader and every configuration dataclass states its ranges as `Range` values and
reports a bad one as an `InputError` whose message names the key as the user wrote it:

    study.toml: tasks.test.fault_durations[0] = nan: must be finite, in [0, inf) s
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Callable


class InputError(ValueError):
    """A value outside its allowed range; `key` names it as written (file and key)."""

    def __init__(self, key: str, value, reason: str, related: tuple[str, ...] = ()):
        """Message "key = value: reason"; without a value (None) key + reason, the reason
        then starting with its own separator (" is empty", ": buses [9] are not ...").
        related: the other fields the reason names ("dt" in "a whole number of steps dt")."""
        super().__init__(key + reason if value is None else f"{key} = {value!r}: {reason}")
        self.key, self.value, self.reason, self.related = key, value, reason, related

    def renamed(self, name: Callable[[str], str],
                source: Callable[[str], str | None] | None = None) -> InputError:
        """The same error with its key as the user wrote it, name(key) (e.g. with the file and
        section in front), and each related field's source(field) (where its value was
        written; None: say nothing) after the reason; source defaults to name."""
        source = source or name
        where = "".join(f" ({r}: {source(r)})" for r in self.related if source(r))
        return InputError(name(self.key), self.value, self.reason + where)


@contextlib.contextmanager
def renamed_errors(name: Callable[[str], str],
                   source: Callable[[str], str | None] | None = None):
    """Re-raise an InputError from inside with its key as the user wrote it, name(key), and
    where its related fields were written, source(field) (`InputError.renamed`)."""
    try:
        yield
    except InputError as err:
        raise err.renamed(name, source) from None


@dataclasses.dataclass(frozen=True)
class Range:
    """An allowed interval of a real value, [lo, hi] (open at an end where flagged), with a unit."""

    lo: float = -math.inf
    hi: float = math.inf
    unit: str = ""
    lo_open: bool = False
    hi_open: bool = False

    def __str__(self) -> str:
        left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
        text = f"{left}{self.lo:g}, {self.hi:g}{right}"
        return f"{text} {self.unit}" if self.unit else text

    def problem(self, value) -> str | None:
        """Why `value` is not allowed ("must be finite, in [0, inf) s"), or None."""
        try:
            number = float(value)
        except (TypeError, ValueError, OverflowError):
            return f"must be a number in {self}"
        if not math.isfinite(number):
            return f"must be finite, in {self}"
        below = number <= self.lo if self.lo_open else number < self.lo
        above = number >= self.hi if self.hi_open else number > self.hi
        return f"must lie in {self}" if below or above else None

    def check(self, key: str, value) -> float:
        """`value` as a float; InputError naming `key` when it is outside the range."""
        reason = self.problem(value)
        if reason:
            raise InputError(key, value, reason)
        return float(value)

    def negated(self) -> Range:
        """The range of −x (for a key that stores the negative of a field)."""
        return Range(-self.hi, -self.lo, self.unit, self.hi_open, self.lo_open)


def check_each(key: str, values, allowed: Range) -> tuple[float, ...]:
    """Every entry of `values` checked; the error names `key[i]`."""
    return tuple(allowed.check(f"{key}[{i}]", v) for i, v in enumerate(values))


def check_int(key: str, value, allowed: Range) -> int:
    """`value` unless it is not an int (a bool is not) inside `allowed`: InputError naming
    `key`."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(key, value, f"must be an integer in {allowed}")
    allowed.check(key, value)
    return value


def check_unique(key: str, values, same=lambda v: v) -> None:
    """InputError naming `key` when an entry repeats (entries compared as same(v), e.g.
    str.lower)."""
    seen = set()
    for v in values:
        if same(v) in seen:
            raise InputError(key, list(values), f"{v} is listed more than once")
        seen.add(same(v))


def check_listed(key: str, values, what: str) -> None:
    """InputError naming `key` when `values` is empty ("give at least one `what`") or an
    entry repeats (a repeat would count twice, e.g. double a task's weight in sampling)."""
    if not len(values):
        raise InputError(key, None, f" is empty: give at least one {what}")
    check_unique(key, values)
