"""The envs' configs check each field's kind against its default's, without importing piga (the envs stay free of the
model and of torch: tests/test_layout.py): a config read from a file's attributes, or built in Python, may hold text
where a number belongs, or a truthy word where a flag does. And the one way an error line writes a checked number, and
a count."""

from __future__ import annotations

import numbers
from decimal import ROUND_CEILING, ROUND_FLOOR, Context
from dataclasses import fields
from typing import Any

import numpy as np

__all__ = ["check_field_kinds", "counted", "lower_bound_text", "number_text", "upper_bound_text"]


def check_field_kinds(config: Any) -> None:
    """Raises a one-line TypeError naming the first field of the dataclass ``config`` whose value is not of the kind of
    its default: a flag (bool) must be True or False, an integer an integer, a number a real number (bool is neither)."""
    for field in fields(config):
        value, default = getattr(config, field.name), field.default
        if isinstance(default, bool):
            kind, what = (bool, np.bool_), "true or false"
        else:
            kind, what = (numbers.Integral, "an integer") if isinstance(default, int) else (numbers.Real, "a number")
        if isinstance(default, (int, float)) and (not isinstance(value, kind) or isinstance(value, (bool, np.bool_))
                                                  != isinstance(default, bool)):
            raise TypeError(f"{type(config).__name__}.{field.name} must be {what}, got {value!r}")


def number_text(value: Any) -> str:
    """A number as an error line writes it: as short as ``g`` writes it (1e+06, 0.5), unless that rounds it (10.0000001
    is not 10, a bound it would seem to meet): then as Python's ``repr`` writes it, the shortest text that reads back
    as the same float (also the shorter for 1e-320, which ``g`` writes 9.99989e-321), less the ``.0`` of a whole
    number (1234567, not 1234567.0). An integer keeps all its digits; a value that is no number (text where one
    belongs, a flag) is written as ``repr`` writes it."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return repr(value)
    if isinstance(value, numbers.Integral):
        return str(int(value))
    value = float(value)
    short, full = format(value, "g"), repr(value).removesuffix(".0")
    return short if float(short) == value and len(short) <= len(full) else full


def counted(n: int, noun: str) -> str:
    """A count as a line writes it: ``n`` and ``noun``, plural (``noun`` + "s") unless ``n`` is 1: "1 sequence",
    "2 sequences"."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def upper_bound_text(bound: float, digits: int) -> str:
    """An upper bound as a range writes it: ``digits`` significant digits, rounded down (π/0.02 as 157.0796 with 7, not
    157.1 with 4, which a refused 157.09 would seem to meet). ``decimal`` rounds down; ``format`` only to nearest."""
    return format(float(Context(prec=digits, rounding=ROUND_FLOOR).create_decimal(bound)), f".{digits}g")


def lower_bound_text(bound: float, digits: int) -> str:
    """A lower bound as a range writes it: ``digits`` significant digits, rounded up (0.6/0.7 as 0.8572 with 4, not
    0.8571, which a refused 0.85714 would seem to meet); :func:`upper_bound_text`'s mirror."""
    return format(float(Context(prec=digits, rounding=ROUND_CEILING).create_decimal(bound)), f".{digits}g")
