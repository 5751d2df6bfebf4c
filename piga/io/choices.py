"""Checking a config dataclass's fixed-choice fields: each field typed ``Literal[...]`` takes one of its values.

A config calls :func:`check_choices` in its ``__post_init__``; the choices come from the annotations
themselves, so that the type and the check cannot disagree. A type checker sees the same ``Literal``.
"""

from __future__ import annotations

import dataclasses
import functools
import typing
from typing import Any, Literal


@functools.cache
def literal_fields(cls: type) -> tuple[tuple[str, tuple[Any, ...]], ...]:
    """(field name, its choices) of each field of the dataclass ``cls`` typed ``Literal[...]``."""
    hints = typing.get_type_hints(cls)
    return tuple((f.name, typing.get_args(hints[f.name])) for f in dataclasses.fields(cls)
                 if typing.get_origin(hints[f.name]) is Literal)


def check_choices(config: Any) -> None:
    """Raises a one-line ValueError naming the first ``Literal`` field of ``config`` whose value is not one of its choices."""
    for name, choices in literal_fields(type(config)):
        value = getattr(config, name)
        if value not in choices:
            raise ValueError(f"{type(config).__name__}.{name} must be one of {', '.join(map(repr, choices))}; got {value!r}")


__all__ = ["check_choices", "literal_fields"]
