"""The wire schema's field checks (contract/schema.py): each field kind accepts exactly what it declares."""

from __future__ import annotations

import math
from typing import Annotated

import pytest
from hypothesis import given
from hypothesis import strategies as st

from auv_swarm.contract import wire
from auv_swarm.contract.schema import INT64_MAX, INT64_MIN, Distinct, MaxLen, OneOf, Range, checker

anything = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(),
    st.text(max_size=8),
    st.binary(max_size=8),
    st.lists(st.integers(-3, 3), max_size=4),
)


def _outcome(check: object, value: object) -> tuple[bool, object]:
    try:
        return True, check(value, "M.f")  # type: ignore[operator]
    except ValueError as exc:
        assert str(exc).startswith("M.f"), str(exc)
        return False, str(exc)


@given(anything)
def test_a_bool_field_takes_bools_only(value: object) -> None:
    ok, out = _outcome(checker(bool), value)
    assert ok == isinstance(value, bool)
    assert ok or str(out).startswith("M.f must be a bool, got ")


@given(st.integers(-5, 5), st.integers(0, 5), anything)
def test_an_int_field_takes_ints_in_its_range_and_never_a_bool(lo: int, width: int, value: object) -> None:
    ok, out = _outcome(checker(Annotated[int, Range(lo, lo + width)]), value)
    is_int = isinstance(value, int) and not isinstance(value, bool)
    assert ok == (is_int and lo <= value <= lo + width)  # type: ignore[operator]
    assert not ok or (out == value and type(out) is int)
    assert _outcome(checker(int), INT64_MAX)[0] and not _outcome(checker(int), INT64_MAX + 1)[0]
    assert _outcome(checker(int), INT64_MIN)[0] and not _outcome(checker(int), INT64_MIN - 1)[0]


@given(st.one_of(anything, st.floats(-2.0, 2.0)))
def test_a_float_field_takes_finite_numbers_in_its_range(value: object) -> None:
    ok, out = _outcome(checker(Annotated[float, Range(-1.0, 1.0)]), value)
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    assert ok == (number and math.isfinite(float(value)) and -1.0 <= value <= 1.0)  # type: ignore[arg-type,operator]
    assert not ok or (out == value and type(out) is float)


@given(anything)
def test_an_optional_field_passes_none_and_checks_the_rest(value: object) -> None:
    ok, out = _outcome(checker(Annotated[int, Range(0, 3)] | None), value)
    assert ok == (value is None or _outcome(checker(Annotated[int, Range(0, 3)]), value)[0])


@given(st.text(max_size=6), st.binary(max_size=6))
def test_strings_and_bytes_are_capped_and_choices_hold(text: str, data: bytes) -> None:
    assert _outcome(checker(Annotated[str, MaxLen(3)]), text)[0] == (len(text) <= 3)
    assert _outcome(checker(Annotated[str, OneOf(("a", "bc"))]), text)[0] == (text in ("a", "bc"))
    assert _outcome(checker(Annotated[bytes, MaxLen(3)]), data)[0] == (len(data) <= 3)
    from_bytearray = _outcome(checker(Annotated[bytes, MaxLen(3)]), bytearray(data))
    assert from_bytearray[0] == (len(data) <= 3) and (not from_bytearray[0] or from_bytearray[1] == data)
    assert not _outcome(checker(bytes), text)[0] and not _outcome(checker(str), data)[0]


@given(st.lists(st.integers(0, 4), max_size=6))
def test_arrays_cap_exact_length_and_distinct_items(items: list[int]) -> None:
    capped = checker(Annotated[tuple[int, ...], MaxLen(4)])
    exact = checker(Annotated[tuple[int, ...], MaxLen(4, exact=True)])
    distinct = checker(Annotated[tuple[int, ...], MaxLen(6), Distinct()])
    assert _outcome(capped, items) == ((True, tuple(items)) if len(items) <= 4 else (False, _outcome(capped, items)[1]))
    assert _outcome(exact, items)[0] == (len(items) == 4)
    assert _outcome(distinct, items)[0] == (len(set(items)) == len(items))
    record = checker(tuple[int, bool])
    assert _outcome(record, items)[0] == (len(items) == 2 and items[1] is True)  # an int is never a bool


@given(st.dictionaries(st.integers(-1, 6), st.integers(-1, 3), max_size=6))
def test_maps_cap_and_check_every_key_and_value(entries: dict[int, int]) -> None:
    check = checker(Annotated[dict[Annotated[int, Range(0, 5)], Annotated[int, Range(0, 3)]], MaxLen(4)])
    fits = len(entries) <= 4 and all(0 <= k <= 5 and 0 <= v <= 3 for k, v in entries.items())
    assert _outcome(check, entries) == ((True, entries) if fits else (False, _outcome(check, entries)[1]))


def test_the_error_lines_name_the_field_and_the_rule() -> None:
    cases = [
        (checker(Annotated[tuple[int, ...], MaxLen(2, exact=True)]), [1], "M.f must be an array of exactly 2 items"),
        (checker(Annotated[tuple[int, ...], MaxLen(2)]), [1, 2, 3], "M.f must be an array of at most 2 items"),
        (checker(Annotated[dict[int, int], MaxLen(1)]), {1: 1, 2: 2}, "M.f must be a map of at most 1 entries"),
        (checker(dict[Annotated[int, Range(0, 1)], int]), {7: 1}, "M.f key must be an integer in [0, 1]"),
        (checker(dict[int, bool]), {7: 1}, "M.f[7] must be a bool"),
        (checker(float), 10**400, "M.f must be a finite number, got"),
        (checker(str), "s" * 257, "M.f must be a string of at most 256 characters"),
    ]
    for check, value, line in cases:
        ok, out = _outcome(check, value)
        assert not ok and str(out).startswith(line), out


def test_every_message_field_has_a_check_and_an_unknown_annotation_is_refused() -> None:
    assert all(len(spec.fields) == len(spec.cls.__dataclass_fields__) - 1 for spec in wire._BY_TYPE.values())
    with pytest.raises(TypeError, match="no checker"):
        checker(complex)
