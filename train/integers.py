"""Integral numbers as a config may write them: ``2000000``, ``2e6``, ``2.0e6``,
``2_000_000``, ``2000000.0``.

PyYAML reads ``2e6`` and ``2.0e6`` (an exponent without a sign) as text, ``2000000.0``
as a float and ``2_000_000`` as an integer; :func:`integral` accepts each of them (and
the same as text) where the value is a whole number, and nothing else.

>>> [integral(v) for v in (2_000_000, "2e6", "2.0e6", "2_000_000", 2000000.0, " 3 ")]
[2000000, 2000000, 2000000, 2000000, 2000000, 3]
>>> [integral(v) for v in (2.5, "2.5e0", "inf", float("nan"), True, "six", None)]
[None, None, None, None, None, None, None]
>>> check_integer("total_timesteps", "2.5e6", low=1)
2500000
>>> check_integer("total_timesteps", 2.5, low=1)
Traceback (most recent call last):
...
ValueError: total_timesteps must be an integer >= 1 (2e6 and 2_000_000 accepted), got 2.5
"""

from __future__ import annotations

import dataclasses
import re
import typing
from collections.abc import Mapping
from decimal import Decimal, InvalidOperation
from typing import Any

import numpy as np

__all__ = ["ACCEPTED", "check_integer", "coerce_integer_fields", "integral"]

#: How an error message says which spellings are accepted.
ACCEPTED = "2e6 and 2_000_000 accepted"

_TEXT = re.compile(r"[-+]?(\d(_?\d)*)?(\.(\d(_?\d)*)?)?([eE][-+]?\d+)?")


def integral(value: Any) -> int | None:
    """``value`` as an ``int`` when it is a whole number (see the module docstring), else
    None. Booleans are no numbers here."""
    if isinstance(value, bool) or isinstance(value, np.bool_):
        return None
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, str):
        text = value.strip()
        if not text or not _TEXT.fullmatch(text) or not any(c.isdigit() for c in text):
            return None
        try:
            number = Decimal(text)
        except InvalidOperation:
            return None
    elif isinstance(value, (float, np.floating)):
        if not np.isfinite(value):
            return None
        number = Decimal(float(value))
    else:
        return None
    if number != number.to_integral_value():
        return None
    return int(number)


def check_integer(key: str, value: Any, *, low: int, high: int | None = None) -> int:
    """``value`` as an integer in ``[low, high]`` (:func:`integral`), or ``ValueError``
    naming ``key``, the allowed range and the accepted spellings."""
    n = integral(value)
    if n is None or n < low or (high is not None and n > high):
        allowed = f"in [{low}, {high}]" if high is not None else f">= {low}"
        raise ValueError(f"{key} must be an integer {allowed} ({ACCEPTED}), got {value!r}")
    return n


def coerce_integer_fields(cls: type, data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` (keys of dataclass ``cls``) with the integral values of its ``int``
    fields, nested dataclass sections included, turned into ``int``.

    Values that are not integral, unknown keys and other fields are left as they are,
    for ``cls`` itself to refuse or accept.
    """
    if not dataclasses.is_dataclass(cls):
        return dict(data)
    hints = typing.get_type_hints(cls)
    out = dict(data)
    for key, value in data.items():
        tp = hints.get(key) if isinstance(key, str) else None
        if tp is int:
            n = integral(value)
            if n is not None:
                out[key] = n
        elif isinstance(tp, type) and dataclasses.is_dataclass(tp) and isinstance(value, Mapping):
            out[key] = coerce_integer_fields(tp, value)
    return out
