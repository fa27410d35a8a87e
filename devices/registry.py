"""Opening rigs by name: ``"virtual:cornell"``, ``"opencv:0"``, ``"replay:PATH"``, ...

Each backend registers an opener and a probe. A probe says whether the backend can be used
on this machine and, if not, why (library missing, no camera attached, no second screen).
Backends are imported lazily so an optional library's absence never breaks ``import devices``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from engine.errors import DeviceError, InputError

# backend name -> module implementing ``open_rig(arg, **options) -> Rig`` and ``probe() -> list[Availability]``
_BACKENDS = {
    "virtual": "devices.virtual",
    "replay": "devices.replay",
    "opencv": "devices.opencv_camera",
    "hotfolder": "devices.hotfolder",
    "gphoto2": "devices.gphoto2_camera",
    "harvesters": "devices.harvesters_camera",
    "mitsuba": "devices.mitsuba",
}


@dataclass(frozen=True)
class Availability:
    """One entry of :func:`available`: a rig name and whether it can be opened here."""

    name: str
    ok: bool
    reason: str = ""

    def __str__(self) -> str:
        return f"{self.name}: {'available' if self.ok else 'unavailable'}{' — ' + self.reason if self.reason else ''}"


def _module(backend: str):
    try:
        return importlib.import_module(_BACKENDS[backend])
    except KeyError:
        raise InputError(f"unknown rig backend {backend!r}; expected one of {sorted(_BACKENDS)}") from None


def available() -> list[Availability]:
    """List what can be opened on this machine, and why the rest can't.

    Returns
    -------
    list of Availability
        One entry per openable name (e.g. every virtual scene) or per unavailable backend.
    """
    out: list[Availability] = []
    for backend in _BACKENDS:
        try:
            mod = _module(backend)
        except ImportError as exc:  # the backend's own module failed to import
            out.append(Availability(f"{backend}:", False, f"cannot import: {exc}"))
            continue
        probe = getattr(mod, "probe", None)
        if probe is None:
            continue
        out.extend(probe())
    return out


def open_rig(name: str, **options):
    """Open a rig by name, e.g. ``open_rig("virtual:cornell", ideal=True)``.

    Parameters
    ----------
    name : str
        ``"backend:argument"``; the argument's meaning is the backend's (a scene, a camera
        index, a session path).
    **options
        Backend options, validated by the backend.

    Returns
    -------
    devices.base.Rig

    Raises
    ------
    InputError
        Unknown backend or bad options.
    DeviceError
        The backend exists but the device can't be opened.
    """
    backend, _, arg = str(name).partition(":")
    mod = _module(backend)
    opener = getattr(mod, "open_rig", None)
    if opener is None:
        raise DeviceError(f"backend {backend!r} has no rig opener")
    return opener(arg, **options)
