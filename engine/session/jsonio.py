"""Plain JSON in and out of a session: numpy values become lists and numbers, nothing else is accepted."""

from __future__ import annotations

import json
from typing import Any

from engine.errors import InputError

__all__ = ["dumps", "loads", "to_json"]


def _default(value):
    import numpy as np

    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (tuple, set, frozenset)):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def to_json(name: str, value) -> Any:
    """Return ``value`` as plain JSON data (numpy arrays become lists), or raise InputError naming ``name``.

    Examples
    --------
    >>> import numpy as np
    >>> to_json("state", {"kappa": np.float32([0.5, 2])})
    {'kappa': [0.5, 2.0]}
    """
    try:
        return json.loads(json.dumps(value, default=_default, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be JSON-serialisable (finite numbers, strings, lists, dicts): {exc}") from exc


def _refuse_constant(name: str):
    raise ValueError(f"non-standard JSON constant {name}")


def loads(text: str) -> Any:
    """Parse strict JSON (no ``NaN``/``Infinity``); ValueError or RecursionError if it is not."""
    return json.loads(text, parse_constant=_refuse_constant)


def dumps(value) -> str:
    """The manifest's text form: indented, UTF-8, finite numbers only, one trailing newline."""
    return json.dumps(value, indent=1, ensure_ascii=False, allow_nan=False) + "\n"
