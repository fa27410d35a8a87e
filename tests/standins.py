"""Keeping scripted stand-ins of vendor libraries honest.

A test stand-in declares which real object it imitates with :func:`stands_in_for`; each test
module checks its stand-ins with :func:`check_standin` whenever the real library is installed:
every public method of the stand-in must exist on the real object and accept every way the
stand-in can be called (and the real method must need no argument the stand-in lets a caller
leave out), every declared attribute must exist, and module constants must have the real
values. A stand-in that drifts from the library fails here, not on the day a lab plugs a
camera in.

Signatures come from :func:`inspect.signature` when the real object has one, else from its
docstring: SWIG bindings (python-gphoto2) start theirs with ``name(self, a, b, context)`` and
mark optional parameters ``(default=...)``; OpenCV's start with ``name(a, b[, c]) -> ret``.

:class:`ModuleBlocker` makes installed libraries look absent (``pytest --without-vendor-libraries``,
and the ``without_modules`` fixture of the device tests).
"""

from __future__ import annotations

import importlib
import inspect
import re

_P = inspect.Parameter


def stands_in_for(target: str, *, attributes: tuple[str, ...] = (), constructed: bool = False):
    """Class decorator: this stand-in imitates ``target`` (``"module:Qualified.name"``).

    ``attributes`` names instance attributes the stand-in sets (checked to exist on the real
    class); its public methods and properties are found by inspection. ``constructed``: the code
    under test creates these objects itself, so ``__init__`` is checked too (otherwise the
    library creates them and the stand-in's constructor is the test's own business).
    """

    def mark(cls):
        cls.__standin_target__ = target
        cls.__standin_attributes__ = tuple(attributes)
        cls.__standin_constructed__ = constructed
        return cls

    return mark


def resolve(target: str):
    """The real object ``"module:Qualified.name"`` names (ImportError if the module is missing)."""
    module_name, _, qualname = target.partition(":")
    obj = importlib.import_module(module_name)
    for part in qualname.split(".") if qualname else ():
        obj = getattr(obj, part)
    return obj


def _docstring_signature(obj) -> inspect.Signature:
    doc = inspect.getdoc(obj) or ""
    match = re.search(r"^\s*\w+\((.*?)\)", doc, re.M)
    if match is None:
        raise ValueError(f"no signature for {obj!r} (no docstring signature either)")
    text = match.group(1)
    required_text, _, optional_text = text.partition("[")
    names = [n.strip() for n in required_text.split(",") if n.strip()]
    optional = [n.strip(" ,[]") for n in optional_text.replace("]", "").split(",") if n.strip(" ,[]")]
    defaults = set(re.findall(r"^(\w+): .*\(default=", doc, re.M))
    params = [_P(n, _P.POSITIONAL_OR_KEYWORD, default=None if n in defaults else _P.empty) for n in names]
    params += [_P(n, _P.POSITIONAL_OR_KEYWORD, default=None) for n in optional]
    return inspect.Signature(params)


def signature(obj) -> inspect.Signature:
    """``inspect.signature`` of ``obj``, or the one its docstring states (C extensions)."""
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        sig = _docstring_signature(obj)
    params = list(sig.parameters.values())
    if params and params[0].name == "self":
        sig = sig.replace(parameters=params[1:])
    return sig


def _calls(sig: inspect.Signature):
    """Representative calls ``(args, kwargs)`` a stand-in with this signature accepts."""
    params = list(sig.parameters.values())
    positional = [p for p in params if p.kind in (_P.POSITIONAL_ONLY, _P.POSITIONAL_OR_KEYWORD)]
    keyword_only = [p for p in params if p.kind == _P.KEYWORD_ONLY]
    required = [p for p in positional if p.default is _P.empty]
    needed_kw = {p.name: 0 for p in keyword_only if p.default is _P.empty}
    for n in range(len(required), len(positional) + 1):
        yield tuple(range(n)), dict(needed_kw)
    for p in keyword_only:
        yield tuple(range(len(required))), {**needed_kw, p.name: 0}


def _required(sig: inspect.Signature) -> int:
    """How many positional arguments a call must give."""
    positional = (_P.POSITIONAL_ONLY, _P.POSITIONAL_OR_KEYWORD)
    return sum(1 for p in sig.parameters.values() if p.default is _P.empty and p.kind in positional)


def _check_callable(label: str, standin, real) -> list[str]:
    problems = []
    theirs, ours = signature(real), signature(standin)
    for args, kwargs in _calls(ours):
        try:
            theirs.bind(*args, **kwargs)
        except TypeError as exc:
            problems.append(f"{label}: the stand-in accepts {len(args)} positional and {sorted(kwargs)} keyword "
                            f"arguments, the real {theirs} does not ({exc})")
    ours_required, theirs_required = _required(ours), _required(theirs)
    if theirs_required > ours_required and not any(p.kind == _P.VAR_POSITIONAL for p in ours.parameters.values()):
        problems.append(
            f"{label}: the real {theirs} requires {theirs_required} arguments, the stand-in {ours} only {ours_required}"
        )
    return problems


def check_standin(cls) -> list[str]:
    """Every way ``cls`` (a :func:`stands_in_for` class) differs from the real object it imitates."""
    real = resolve(cls.__standin_target__)
    label = f"{cls.__name__} (for {cls.__standin_target__})"
    problems: list[str] = []
    for name, member in vars(cls).items():
        dunders = ("__getitem__", "__len__", "__iter__", "__enter__", "__exit__", "__call__")
        if name.startswith("_") and name not in dunders and not (name == "__init__" and cls.__standin_constructed__):
            continue
        if not hasattr(real, name):
            problems.append(f"{label}: the real object has no {name!r}")
            continue
        if isinstance(member, property):
            continue
        if isinstance(member, classmethod):
            problems += _check_callable(f"{label}.{name}", member.__get__(None, cls), getattr(real, name))
        elif isinstance(member, staticmethod):
            member = member.__func__
            problems += _check_callable(f"{label}.{name}", member, getattr(real, name))
        elif inspect.isfunction(member):
            problems += _check_callable(f"{label}.{name}", member, getattr(real, name))
        elif isinstance(member, (int, float, str)) and isinstance(getattr(real, name), (int, float, str)):
            if getattr(real, name) != member:  # a module constant
                problems.append(f"{label}: {name} is {member!r}, the real one {getattr(real, name)!r}")
    for name in cls.__standin_attributes__:
        if not hasattr(real, name):
            problems.append(f"{label}: the real object has no attribute {name!r}")
    return problems


#: the optional vendor libraries (``pip install 'albedit[gphoto2,harvesters]'``)
VENDOR_LIBRARIES = ("gphoto2", "harvesters", "genicam")


class ModuleBlocker:
    """A ``sys.meta_path`` finder that makes ``import NAME`` fail as if NAME were not installed."""

    def __init__(self, names):
        self.names = frozenset(names)

    def find_spec(self, fullname, path=None, target=None):
        if fullname.partition(".")[0] in self.names:
            raise ModuleNotFoundError(f"No module named {fullname!r}", name=fullname)
        return None
