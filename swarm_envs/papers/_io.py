"""Shared output helpers of the reproductions (JSON-ready values, JSON files)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["to_jsonable", "write_json"]


def to_jsonable(obj: Any, digits: int = 6) -> Any:
    """Nested dicts/lists of numpy values → plain Python, floats to ``digits`` figures.

    Non-finite floats become ``None`` (JSON has no ``inf``/``NaN``).

    >>> to_jsonable({"a": np.float64(1.23456789), "b": [np.inf, 2]})
    {'a': 1.23457, 'b': [None, 2]}
    """
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v, digits) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist(), digits)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        value = float(obj)
        if not math.isfinite(value):
            return None
        return float(f"{value:.{digits}g}")
    if isinstance(obj, Path):
        return obj.name
    return obj


def write_json(path: str | Path, doc: Any, *, indent: int = 1) -> Path:
    """Write ``doc`` (made JSON-ready with :func:`to_jsonable`) to ``path``; return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(to_jsonable(doc), indent=indent, ensure_ascii=False) + "\n")
    return path
