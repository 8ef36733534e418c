"""The wire schema's field kinds: the constraints a message field declares and the check each becomes.

A field of a :mod:`contract.wire` message is annotated with its type and, in ``Annotated``, its
constraints (:class:`Range`, :class:`MaxLen`, :class:`OneOf`, :class:`Distinct`). :func:`checker` turns
one annotation into a small check object, once per message field; ``check(value, where)`` returns the
value's canonical form (a tuple for an array, a float for an int given as a number) or raises
ValueError naming ``where``. The encoder and the decoder share these checks.
"""

from __future__ import annotations

import math
import types
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any, Union, get_args, get_origin

MAX_PAYLOAD_BYTES = 65536
"""The largest bytes value on the wire (one acoustic payload), the cap of a bytes field that declares none."""
MAX_ARRAY = 1024
"""The cap of an array or map field that declares none."""
INT64_MIN = -(2**63)
INT64_MAX = 2**63 - 1
FLOAT_MAX = 1.7976931348623157e308


@dataclass(frozen=True)
class Range:
    """A number field's closed range [lo, hi]; None is an open end."""

    lo: float | None = None
    hi: float | None = None


@dataclass(frozen=True)
class MaxLen:
    """A string, bytes, array or map field's length cap (``exact``: an array of exactly ``n`` items)."""

    n: int
    exact: bool = False


@dataclass(frozen=True)
class OneOf:
    """A string field's allowed values."""

    choices: tuple[str, ...]


@dataclass(frozen=True)
class Distinct:
    """An array field whose items must not repeat."""


Checker = Callable[[Any, str], Any]
"""A field check: ``check(value, where)`` returns the value's canonical form or raises ValueError naming ``where``."""


def short_repr(value: Any) -> str:
    """``repr(value)``, cut to 60 characters for an error line."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _range_text(lo: float | None, hi: float | None) -> str:
    return f"[{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"


@dataclass(frozen=True, slots=True)
class _OptionalCheck:
    """``T | None``: None passes as is, anything else is checked as ``T``."""

    inner: Checker

    def __call__(self, v: Any, where: str) -> Any:
        return None if v is None else self.inner(v, where)


@dataclass(frozen=True, slots=True)
class _BoolCheck:
    """A bool, and only a bool (0 and 1 are not)."""

    def __call__(self, v: Any, where: str) -> bool:
        if not isinstance(v, bool):
            raise ValueError(f"{where} must be a bool, got {short_repr(v)}")
        return v


@dataclass(frozen=True, slots=True)
class _IntCheck:
    """An integer (not a bool) in ``[lo, hi]``."""

    lo: int
    hi: int

    def __call__(self, v: Any, where: str) -> int:
        if isinstance(v, bool) or not isinstance(v, int) or not self.lo <= v <= self.hi:
            raise ValueError(f"{where} must be an integer in {_range_text(self.lo, self.hi)}, got {short_repr(v)}")
        return int(v)


@dataclass(frozen=True, slots=True)
class _FloatCheck:
    """A finite number (an int is widened, a bool is not a number) in ``[lo, hi]``; None is an open end."""

    lo: float | None
    hi: float | None

    def __call__(self, v: Any, where: str) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or abs(v) > FLOAT_MAX:
            raise ValueError(f"{where} must be a finite number, got {short_repr(v)}")
        x = float(v)
        if not math.isfinite(x) or (self.lo is not None and x < self.lo) or (self.hi is not None and x > self.hi):
            raise ValueError(f"{where} must be a finite number in {_range_text(self.lo, self.hi)}, got {short_repr(v)}")
        return x


@dataclass(frozen=True, slots=True)
class _StrCheck:
    """A string of at most ``cap`` characters, one of ``choices`` when given."""

    cap: int
    choices: tuple[str, ...] | None

    def __call__(self, v: Any, where: str) -> str:
        if not isinstance(v, str) or len(v) > self.cap:
            raise ValueError(f"{where} must be a string of at most {self.cap} characters, got {short_repr(v)}")
        if self.choices is not None and v not in self.choices:
            raise ValueError(f"{where} must be one of {', '.join(self.choices)}, got {short_repr(v)}")
        return v


@dataclass(frozen=True, slots=True)
class _BytesCheck:
    """Bytes (or a bytearray, returned as bytes) of length at most ``cap``."""

    cap: int

    def __call__(self, v: Any, where: str) -> bytes:
        if not isinstance(v, (bytes, bytearray)) or len(v) > self.cap:
            raise ValueError(f"{where} must be bytes of length at most {self.cap}, got {short_repr(v)}")
        return bytes(v)


@dataclass(frozen=True, slots=True)
class _ArrayCheck:
    """``tuple[T, ...]``: at most (``exact``: exactly) ``cap`` items, each checked; ``distinct``: no repeats."""

    item: Checker
    cap: int
    exact: bool
    distinct: bool

    def __call__(self, v: Any, where: str) -> tuple[Any, ...]:
        if not isinstance(v, (list, tuple)) or len(v) > self.cap or (self.exact and len(v) != self.cap):
            what = "exactly" if self.exact else "at most"
            raise ValueError(f"{where} must be an array of {what} {self.cap} items, got {short_repr(v)}")
        out = tuple(self.item(x, f"{where}[{i}]") for i, x in enumerate(v))
        if self.distinct and len(set(out)) != len(out):
            raise ValueError(f"{where} must not repeat an item, got {short_repr(v)}")
        return out


@dataclass(frozen=True, slots=True)
class _RecordCheck:
    """``tuple[A, B, ...]``: exactly one item per type, each checked by its own check."""

    items: tuple[Checker, ...]

    def __call__(self, v: Any, where: str) -> tuple[Any, ...]:
        if not isinstance(v, (list, tuple)) or len(v) != len(self.items):
            raise ValueError(f"{where} must be an array of exactly {len(self.items)} items, got {short_repr(v)}")
        return tuple(c(x, f"{where}[{i}]") for i, (c, x) in enumerate(zip(self.items, v, strict=True)))


@dataclass(frozen=True, slots=True)
class _MapCheck:
    """``dict[K, V]``: at most ``cap`` entries, every key and value checked."""

    key: Checker
    value: Checker
    cap: int

    def __call__(self, v: Any, where: str) -> dict[Any, Any]:
        if not isinstance(v, dict) or len(v) > self.cap:
            raise ValueError(f"{where} must be a map of at most {self.cap} entries, got {short_repr(v)}")
        out = {}
        for k, x in v.items():
            key = self.key(k, f"{where} key")
            out[key] = self.value(x, f"{where}[{key!r}]")
        return out


@dataclass(frozen=True)
class _Constraints:
    """The ``Annotated`` extras of one annotation: range, length cap, choices, no repeats."""

    range: Range = Range()
    size: MaxLen | None = None
    choices: tuple[str, ...] | None = None
    distinct: bool = False

    @classmethod
    def split(cls, tp: Any) -> tuple[Any, _Constraints]:
        """(the bare type, its constraints) of ``tp``, ``Annotated`` or not."""
        if get_origin(tp) is not Annotated:
            return tp, cls()
        tp, *extras = get_args(tp)
        return tp, cls(
            range=next((e for e in extras if isinstance(e, Range)), Range()),
            size=next((e for e in extras if isinstance(e, MaxLen)), None),
            choices=next((e.choices for e in extras if isinstance(e, OneOf)), None),
            distinct=any(isinstance(e, Distinct) for e in extras),
        )

    def cap(self, default: int) -> int:
        """The length cap, or ``default`` when none is declared."""
        return default if self.size is None else self.size.n


def _int_check(c: _Constraints) -> Checker:
    lo = INT64_MIN if c.range.lo is None else int(c.range.lo)
    hi = INT64_MAX if c.range.hi is None else int(c.range.hi)
    return _IntCheck(lo, hi)


_SCALAR_CHECKS: dict[type, Callable[[_Constraints], Checker]] = {
    bool: lambda c: _BoolCheck(),
    int: _int_check,
    float: lambda c: _FloatCheck(c.range.lo, c.range.hi),
    str: lambda c: _StrCheck(c.cap(256), c.choices),
    bytes: lambda c: _BytesCheck(c.cap(MAX_PAYLOAD_BYTES)),
}
"""How each scalar field kind is checked, given its constraints."""


def checker(tp: Any) -> Checker:
    """The check object for one value of annotation ``tp`` (built once per message field)."""
    tp, c = _Constraints.split(tp)
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        (inner,) = [a for a in get_args(tp) if a is not type(None)]
        return _OptionalCheck(checker(inner))
    if tp in _SCALAR_CHECKS:
        return _SCALAR_CHECKS[tp](c)
    if origin is tuple:
        args = get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            exact = c.size is not None and c.size.exact
            return _ArrayCheck(checker(args[0]), c.cap(MAX_ARRAY), exact, c.distinct)
        return _RecordCheck(tuple(checker(a) for a in args))
    if origin is dict:
        key_tp, value_tp = get_args(tp)
        return _MapCheck(checker(key_tp), checker(value_tp), c.cap(MAX_ARRAY))
    raise TypeError(f"wire: no checker for annotation {tp!r}")
