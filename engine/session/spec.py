"""Declarative checks of JSON data: each field's type and range, refused with the field's path.

A spec is a small object with ``check(value, path)``; a refusal raises :class:`Invalid` naming
the path in the form a reader finds in the file (``state.plan.order``,
``captures[3].meta.exposure``, ``masks["wall"].shape``). The session manifest
(:mod:`engine.session.schema`) and the saved edit (:mod:`engine.session.edit`) are written with
these; callers turn :class:`Invalid` into their own error type.

Examples
--------
>>> spec = Obj(required={"order": Int(1, 8)}, optional={"kappa": Num(0)})
>>> spec.check({"order": 3}, "plan")
>>> try:
...     spec.check({"order": "3"}, "plan")
... except Invalid as exc:
...     print(exc)
plan.order must be an integer in [1, 8], got '3'
"""

from __future__ import annotations

import abc
import math
import re
from collections.abc import Callable, Mapping

__all__ = [
    "ANY", "Bool", "Const", "Custom", "Int", "Invalid", "List", "Map", "Nullable", "Num", "Obj", "OneOf", "Spec", "Str",
    "join",
]

_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class Invalid(ValueError):
    """A value does not fit its spec; ``path`` names the field, ``str(exc)`` says what was expected.

    ``message`` replaces the default ``"<path> must be <expected>, got <value>"``.
    """

    def __init__(self, path: str, expected: str, value, *, message: str | None = None) -> None:
        self.path = path
        self.expected = expected
        shown = repr(value)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        super().__init__(message or f"{path} must be {expected}, got {shown}")


def join(path: str, key) -> str:
    """The path of ``key`` inside ``path``: ``a.b`` for plain names, ``a["x y"]`` otherwise, ``a[3]`` for indices."""
    if isinstance(key, int):
        return f"{path}[{key}]"
    if _IDENTIFIER.fullmatch(key):
        return f"{path}.{key}" if path else key
    quoted = '"' + key.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return f"{path}[{quoted}]"


class Spec(abc.ABC):
    """Base class: ``check(value, path)`` returns None or raises :class:`Invalid`."""

    expected = "a JSON value"

    @abc.abstractmethod
    def check(self, value, path: str) -> None:
        """Return None if ``value`` fits, else raise :class:`Invalid` naming ``path``."""

    def fail(self, path: str, value):
        raise Invalid(path, self.expected, value)


class _Any(Spec):
    def check(self, value, path: str) -> None:
        return None


#: Any JSON value (free-form fields).
ANY = _Any()


def _range(lo, hi, kind: str) -> str:
    if lo is not None and hi is not None:
        return f"{kind} in [{lo:g}, {hi:g}]"
    if lo is not None:
        return f"{kind} >= {lo:g}"
    if hi is not None:
        return f"{kind} <= {hi:g}"
    return kind


class Int(Spec):
    """An integer (not a bool) in ``[lo, hi]`` (either bound optional)."""

    def __init__(self, lo: int | None = None, hi: int | None = None) -> None:
        self.lo, self.hi = lo, hi
        self.expected = _range(lo, hi, "an integer")

    def check(self, value, path: str) -> None:
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(path, value)
        if (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
            self.fail(path, value)


class Num(Spec):
    """A finite number (int or float, not a bool) in ``[lo, hi]``; ``positive`` excludes 0."""

    def __init__(self, lo: float | None = None, hi: float | None = None, *, positive: bool = False) -> None:
        self.lo, self.hi, self.positive = lo, hi, positive
        self.expected = "a positive number" if positive and lo is None and hi is None else _range(lo, hi, "a number")

    def check(self, value, path: str) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(path, value)
        try:
            x = float(value)
        except OverflowError:  # an integer beyond float range
            self.fail(path, value)
        if not math.isfinite(x) or (self.positive and x <= 0):
            self.fail(path, value)
        if (self.lo is not None and x < self.lo) or (self.hi is not None and x > self.hi):
            self.fail(path, value)


class Bool(Spec):
    expected = "true or false"

    def check(self, value, path: str) -> None:
        if not isinstance(value, bool):
            self.fail(path, value)


class Str(Spec):
    """A string; optionally matching ``pattern``, one of ``choices``, of at most ``max_len`` characters."""

    def __init__(self, *, pattern: str | None = None, choices=None, max_len: int = 4096, min_len: int = 0,
                 expected: str | None = None) -> None:
        self.pattern = None if pattern is None else re.compile(pattern)
        self.choices = None if choices is None else tuple(choices)
        self.max_len, self.min_len = max_len, min_len
        if expected is not None:
            self.expected = expected
        elif self.choices is not None:
            self.expected = "one of " + ", ".join(repr(c) for c in self.choices)
        else:
            self.expected = "a non-empty string" if min_len else "a string"

    def check(self, value, path: str) -> None:
        if not isinstance(value, str) or not self.min_len <= len(value) <= self.max_len:
            self.fail(path, value)
        if self.pattern is not None and not self.pattern.fullmatch(value):
            self.fail(path, value)
        if self.choices is not None and value not in self.choices:
            self.fail(path, value)


class Const(Spec):
    def __init__(self, value) -> None:
        self.value = value
        self.expected = repr(value)

    def check(self, value, path: str) -> None:
        if type(value) is not type(self.value) or value != self.value:
            self.fail(path, value)


class Nullable(Spec):
    """``null`` or ``spec``."""

    def __init__(self, spec: Spec) -> None:
        self.spec = spec
        self.expected = f"null or {spec.expected}"

    def check(self, value, path: str) -> None:
        if value is not None:
            self.spec.check(value, path)


class OneOf(Spec):
    """The first of ``specs`` that accepts the value; else the refusal lists them all."""

    def __init__(self, *specs: Spec, expected: str | None = None) -> None:
        self.specs = specs
        self.expected = expected or " or ".join(s.expected for s in specs)

    def check(self, value, path: str) -> None:
        inner = None
        for spec in self.specs:
            try:
                spec.check(value, path)
                return
            except Invalid as exc:
                if exc.path != path and inner is None:
                    inner = exc  # the value had the right shape but a wrong field: report that
        if inner is not None:
            raise inner
        self.fail(path, value)


class List(Spec):
    """A list of ``item`` values, ``length`` long or ``min_len``..``max_len``."""

    def __init__(self, item: Spec, *, length: int | None = None, min_len: int = 0, max_len: int | None = None,
                 expected: str | None = None) -> None:
        self.item, self.length, self.min_len, self.max_len = item, length, min_len, max_len
        if expected is not None:
            self.expected = expected
        elif length is not None:
            self.expected = f"a list of {length} values ({item.expected})"
        else:
            self.expected = f"a list of {item.expected}" + (" (at least one)" if min_len else "")

    def check(self, value, path: str) -> None:
        if not isinstance(value, list):
            self.fail(path, value)
        n = len(value)
        if (self.length is not None and n != self.length) or n < self.min_len or (
                self.max_len is not None and n > self.max_len):
            self.fail(path, value)
        for i, item in enumerate(value):
            self.item.check(item, join(path, i))


class Obj(Spec):
    """An object with ``required`` and ``optional`` fields; other keys are refused unless ``extra`` checks them."""

    def __init__(self, *, required: Mapping[str, Spec] | None = None, optional: Mapping[str, Spec] | None = None,
                 extra: Spec | None = None, expected: str = "an object") -> None:
        self.required = dict(required or {})
        self.optional = dict(optional or {})
        self.extra = extra
        self.expected = expected

    def check(self, value, path: str) -> None:
        if not isinstance(value, dict):
            self.fail(path, value)
        for key, spec in self.required.items():
            if key not in value:
                where = join(path, key)
                raise Invalid(where, spec.expected, None, message=f"{where} is missing ({spec.expected} expected)")
            spec.check(value[key], join(path, key))
        for key, item in value.items():
            if key in self.required:
                continue
            item_spec = self.optional.get(key, self.extra)
            if item_spec is None:
                known = sorted(self.required) + sorted(self.optional)
                raise Invalid(join(path, key), f"absent (not a known field; known: {', '.join(known)})", item)
            item_spec.check(item, join(path, key))


class Map(Spec):
    """An object whose keys match ``key`` (a :class:`Str`) and whose values match ``value``."""

    def __init__(self, key: Str, value: Spec, *, expected: str | None = None) -> None:
        self.key, self.value = key, value
        self.expected = expected or f"an object of {value.expected}"

    def check(self, value, path: str) -> None:
        if not isinstance(value, dict):
            self.fail(path, value)
        for k, item in value.items():
            try:
                self.key.check(k, join(path, k))
            except Invalid:
                raise Invalid(join(path, k), f"named by {self.key.expected}", k) from None
            self.value.check(item, join(path, k))


class Custom(Spec):
    """A check by ``test(value) -> bool`` with its own words for what is expected."""

    def __init__(self, test: Callable[[object], bool], expected: str) -> None:
        self.test = test
        self.expected = expected

    def check(self, value, path: str) -> None:
        try:
            ok = bool(self.test(value))
        except (TypeError, ValueError, OverflowError):
            ok = False
        if not ok:
            self.fail(path, value)
