"""The envs' configs check each field's kind against its default's, without importing piga (the envs stay free of the
model and of torch: tests/test_layout.py): a config read from a file's attributes, or built in Python, may hold text
where a number belongs, or a truthy word where a flag does."""

from __future__ import annotations

import numbers
from dataclasses import fields
from typing import Any

import numpy as np

__all__ = ["check_field_kinds"]


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
