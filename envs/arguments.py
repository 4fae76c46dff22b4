"""Keyword arguments described as data: the checks of their values, their ``Parameter`` and the Arguments table.

A dataclass field made by ``documented`` carries a ``Parameter`` (type text, one-line description, unit, check,
whether the robot's preset gives the default) in its metadata; ``parameters`` reads them back with the field's name
and default. Their checks (``Range``, ``Choice``, ``Vector``) give messages naming the argument, the expected and
the actual value, and ``table`` / ``attributes`` write the docs from them (``envs.params.FamilyParams``, the
envs' docstrings).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from dataclasses import field, fields
from enum import Enum
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "CONDITION",
    "NON_NEGATIVE",
    "NON_NEGATIVE_INT",
    "POSITIVE",
    "POSITIVE_INT",
    "Choice",
    "Parameter",
    "Range",
    "Vector",
    "attributes",
    "documented",
    "parameters",
    "table",
]


def _number_text(value: float) -> str:
    return f"{value:g}"


class Range(NamedTuple):
    """A finite real number (or, with ``integer``, an int) in an interval; an open end excludes its bound."""

    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False
    integer: bool = False

    @property
    def text(self) -> str:
        """The interval as the messages and the docs write it: "> 0", "≥ 1", "in (0, 1)"."""
        if self.high == math.inf:
            return f"{'>' if self.low_open else '≥'} {_number_text(self.low)}"
        left, right = "(" if self.low_open else "[", ")" if self.high_open else "]"
        return f"in {left}{_number_text(self.low)}, {_number_text(self.high)}{right}"

    def contains(self, value: float) -> bool:
        """Whether ``value`` lies in the interval."""
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return above and below

    def __call__(self, name: str, value: Any, sizes: dict[str, int]) -> float | int:
        """``value`` as a float (an int), or a ``ValueError``/``TypeError`` naming ``name``, the range and ``value``."""
        if self.integer:
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not self.contains(value):
                raise ValueError(f"{name} must be an int {self.text}, got {value!r}")
            return int(value)
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
        value = float(value)
        if not (math.isfinite(value) and self.contains(value)):
            raise ValueError(f"{name} must be finite and {self.text}, got {value!r}")
        return value


class Choice(NamedTuple):
    """One of a few allowed values."""

    values: tuple[str, ...]

    @property
    def text(self) -> str:
        """The allowed values, as the messages write them."""
        return f"one of {self.values}"

    def __call__(self, name: str, value: Any, sizes: dict[str, int]) -> Any:
        """``value``, or a ``ValueError`` naming ``name``, the allowed values and ``value``."""
        if value not in self.values:
            raise ValueError(f"{name} must be {self.text}, got {value!r}")
        return value


class Vector(NamedTuple):
    """A fixed number of finite reals: ``size`` a count, "m" (pose coordinates) or "n" (actuators).

    With ``per_actuator``, () stands for the default (kept as ()) and one number for n equal ones.
    """

    size: int | str
    element: Range | None = None
    per_actuator: bool = False

    @property
    def text(self) -> str:
        """The element range as the docs write it ("each > 0"), or "" for any finite numbers."""
        return "" if self.element is None else f"each {self.element.text}"

    def __call__(self, name: str, value: Any, sizes: dict[str, int]) -> tuple[float, ...]:
        """``value`` as a tuple of floats, or a ``ValueError``/``TypeError`` naming ``name``, the size, ``value``."""
        size = sizes[self.size] if isinstance(self.size, str) else self.size
        if self.per_actuator:
            if isinstance(value, (tuple, list, np.ndarray)) and len(value) == 0:
                return ()
            if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
                value = (value,) * size
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{name} must be a sequence of {size} numbers, got {value!r}") from exc
        if arr.shape != (size,) or not np.isfinite(arr).all():
            raise ValueError(f"{name} must be {size} finite numbers, got {value!r}")
        values = tuple(float(v) for v in arr)
        if self.element is not None and not all(self.element.contains(v) for v in values):
            raise ValueError(f"{name} must be {size} numbers {self.element.text}, got {list(values)}")
        return values


POSITIVE = Range(0.0, low_open=True)
NON_NEGATIVE = Range(0.0)
POSITIVE_INT = Range(1, integer=True)
NON_NEGATIVE_INT = Range(0, integer=True)
#: An inverse condition number k (or k_I) at which something starts: in (0, 1).
CONDITION = Range(0.0, 1.0, low_open=True, high_open=True)


class Parameter(NamedTuple):
    """A keyword argument described in one place: a dataclass field's ``metadata["doc"]`` (see ``documented``).

    Attributes:
        name: The keyword ("" in a field's metadata: ``parameters`` fills it in from the field).
        default: Its default (likewise filled in from the field).
        description: One line: what the value means (the Description cell, before the unit and the range).
        unit: SI unit(s) of the value, "" for a pure number.
        check: The simple check of a value (``Range``, ``Choice``, ``Vector``), or None where the relations
            between arguments decide (``envs.presets.build_family_params``).
        per_robot: Whether a robot's preset (``envs.presets.ROBOT_PRESETS``) or size (``derived_defaults``) may
            give the default in place of the field's (the hexapod's).
        note: More detail for the Attributes of the dataclass's docstring, "" for none.
        type: The Type cell of the Arguments table; "" for the one the check implies ("float", "int", "str",
            "sequence of m floats", "(float, float)", "float or n floats").
    """

    name: str
    default: Any
    description: str
    unit: str = ""
    check: Range | Choice | Vector | None = None
    per_robot: bool = False
    note: str = ""
    type: str = ""

    def type_text(self) -> str:
        """The Type cell: ``type``, else the type the check implies."""
        check = self.check
        if self.type or check is None:
            return self.type
        if isinstance(check, Range):
            return "int" if check.integer else "float"
        if isinstance(check, Choice):
            return "str"
        if check.per_actuator:
            return f"float or {check.size} floats"
        if isinstance(check.size, str):
            return f"sequence of {check.size} floats"
        return "(" + ", ".join(["float"] * check.size) + ")"

    def describe(self) -> str:
        """The Description cell: the description, the unit in brackets and the range of a number or numbers."""
        text = self.description + (f" [{self.unit}]" if self.unit else "")
        if isinstance(self.check, (Range, Vector)) and self.check.text:
            text += f"; {self.check.text}"
        return text


def documented(default: Any, description: str, unit: str = "", check: Any = None, **more: Any) -> Any:
    """A dataclass field with its ``default`` and, as metadata, its ``Parameter`` (description, unit, check, more)."""
    return field(default=default, metadata={"doc": Parameter("", default, description, unit, check, **more)})


def parameters(cls: type, skip: Sequence[str] = ()) -> tuple[Parameter, ...]:
    """The ``Parameter`` of every field of the dataclass ``cls`` (but those named in ``skip``), in field order."""
    undocumented = [f.name for f in fields(cls) if "doc" not in f.metadata]
    if undocumented:
        raise TypeError(f"fields {undocumented} of {cls.__name__} have no Parameter: declare them with documented()")
    return tuple(f.metadata["doc"]._replace(name=f.name, default=f.default) for f in fields(cls) if f.name not in skip)


def _default_cell(parameter: Parameter) -> str:
    value = parameter.default
    if isinstance(value, Enum):
        text = f"{type(value).__name__}.{value.name}"
    else:
        text = f'"{value}"' if isinstance(value, str) else repr(value)
    return f"`{text}`" + (" †" if parameter.per_robot else "")


def table(rows: Sequence[Parameter], indent: str = "    ") -> str:
    """Gymnasium's ``| Parameter | Type | Default | Description |`` table, one row per ``Parameter``, indented.

    The Default cell is the default as a Python literal (strings in double quotes), marked † where ``per_robot``;
    the Description cell is ``Parameter.describe()``.
    """
    lines = ["| Parameter | Type | Default | Description |", "|-----------|------|---------|-------------|"]
    lines += [f"| `{p.name}` | {p.type_text()} | {_default_cell(p)} | {p.describe()} |" for p in rows]
    return "\n".join(indent + line for line in lines)


def attributes(cls: type, indent: str = "        ") -> str:
    """The entries of a Google-style Attributes section, one per field of the dataclass ``cls``, from its metadata."""
    entries = []
    for p in parameters(cls):
        text = p.describe()
        first = text.split(" ", 1)[0]
        if len(first) > 1 and first.isascii() and first.isalpha() and first.islower():  # a word, not a symbol
            text = text[0].upper() + text[1:]
        text = f"{p.name}: {text}." + (f" {p.note}" if p.note else "") + (" †" if p.per_robot else "")
        entries.append(textwrap.fill(text, 116, initial_indent=indent, subsequent_indent=indent + "    "))
    return "\n".join(entries)
