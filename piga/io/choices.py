"""Checking a config dataclass's fields against their annotations: each field typed ``Literal[...]`` takes one of its
values (:func:`check_choices`), and each number, flag, text or tuple is one (:func:`check_types`).

A config calls them in its ``__post_init__``; the choices and types come from the annotations themselves, so that the
type and the check cannot disagree. A type checker sees the same annotations; a program calling the library without
one (a notebook, a script) gets a one-line error naming the field, instead of a comparison failing deep inside.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import types
import typing
from typing import Any, Literal


@functools.cache
def literal_fields(cls: type) -> tuple[tuple[str, tuple[Any, ...]], ...]:
    """(field name, its choices) of each field of the dataclass ``cls`` typed ``Literal[...]``."""
    hints = typing.get_type_hints(cls)
    return tuple((f.name, typing.get_args(hints[f.name])) for f in dataclasses.fields(cls)
                 if typing.get_origin(hints[f.name]) is Literal)


def check_choices(config: Any) -> None:
    """Raises a one-line ValueError naming the first ``Literal`` field of ``config`` whose value is not one of its choices
    (after :func:`check_types`' TypeError for a field of another kind)."""
    check_types(config)
    for name, choices in literal_fields(type(config)):
        value = getattr(config, name)
        if value not in choices:
            raise ValueError(f"{type(config).__name__}.{name} must be one of {', '.join(map(repr, choices))}; got {value!r}")


#: What a value of each checked annotation may be, in words and as a test. bool is an int to Python, never a number
#: here; numpy's integers and floats are numbers.
_KINDS: dict[Any, tuple[str, Any]] = {
    int: ("an integer", lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool)),
    float: ("a number", lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool)),
    bool: ("True or False", lambda v: isinstance(v, bool)),
    str: ("text", lambda v: isinstance(v, str)),
    tuple: ("a tuple", lambda v: isinstance(v, (tuple, list))),
}


@functools.cache
def typed_fields(cls: type) -> tuple[tuple[str, str, Any, bool], ...]:
    """(field name, what it must be in words, its test, whether None is allowed) of each field of the dataclass
    ``cls`` whose annotation is int, float, bool, str or a tuple, alone or ``| None``; None is allowed too where the
    field's default is None (a preset fills it)."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        args = typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, types.UnionType) else (hint,)
        optional = type(None) in args or f.default is None
        kinds = [_KINDS.get(typing.get_origin(a) or a) for a in args if a is not type(None)]
        if len(kinds) == 1 and kinds[0] is not None:
            out.append((f.name, kinds[0][0], kinds[0][1], optional))
    return tuple(out)


def check_types(config: Any) -> None:
    """Raises a one-line TypeError naming the first field of ``config`` whose value is not of its annotated kind
    (:func:`typed_fields`): ``TrainConfig(epochs="3")`` says so, instead of failing later at a comparison."""
    for name, words, test, optional in typed_fields(type(config)):
        value = getattr(config, name)
        if not (test(value) or (optional and value is None)):
            raise TypeError(f"{type(config).__name__}.{name} must be {words}{' or None' if optional else ''}; "
                            f"got {value!r} ({type(value).__name__})")


def check_ranges(config: Any, ranges: dict[str, tuple[float, float]], above: tuple[str, ...] = ()) -> None:
    """Raises a one-line ValueError naming the first field of ``config`` (a number, or None where a preset fills it)
    outside its range in ``ranges``: finite, at least ``low`` (above it, for the fields in ``above``) and at most
    ``high``. NaN and infinities are out of every range: ``lr=inf`` trained to NaN, ``goal_angle=nan`` scored 0."""
    for name, (low, high) in ranges.items():
        value = getattr(config, name)
        if value is None:
            continue
        if not (math.isfinite(value) and (value > low if name in above else value >= low) and value <= high):
            bound = f"{'>' if name in above else '>='} {low:g}" + (f" and <= {high:g}" if high != math.inf else "")
            raise ValueError(f"{type(config).__name__}.{name} must be a finite number {bound}; got {value!r}")


__all__ = ["check_choices", "check_ranges", "check_types", "literal_fields", "typed_fields"]
