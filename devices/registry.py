"""Opening rigs by name: ``"virtual:cornell"``, ``"opencv:0"``, ``"gphoto2"``, ``"replay:PATH"``, ...

Two kinds of backend register here, each a module imported lazily (so an optional library's
absence never breaks ``import devices``):

- a **rig backend** implements ``open_rig(arg, **options) -> Rig`` (the virtual rig, replay, the
  loopback bench); a **camera backend** implements ``open_camera(arg, **options) -> Camera``,
  and :func:`open_rig` pairs its camera with a projector. Both implement ``probe()``: whether
  they can be used on this machine and, if not, why (library missing, no camera attached).
- a **projector backend** implements ``open_projector(arg, **options) -> Projector``,
  ``probe()`` and ``default_problem() -> str`` (why its default projector cannot open here,
  "" if it can). A camera's rig chooses one with ``projector="NAME:ARG"`` (default: the first
  one registered, with its default argument).

Adding a backend is adding one line to :data:`_BACKENDS` or :data:`_PROJECTORS`.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from engine.errors import DeviceError, InputError

# backend name -> module implementing ``open_rig(arg, **options) -> Rig`` or
# ``open_camera(arg, **options) -> Camera``, and ``probe() -> list[Availability]``
_BACKENDS = {
    "virtual": "devices.virtual",
    "replay": "devices.replay",
    "opencv": "devices.opencv_camera",
    "hotfolder": "devices.hotfolder",
    "loopback": "devices.loopback",
    "gphoto2": "devices.gphoto2_camera",
    "harvesters": "devices.harvesters_camera",
    "mitsuba": "devices.mitsuba",
}

# projector backend name -> module implementing ``open_projector(arg, **options) -> Projector``,
# ``probe()`` and ``default_problem()``; the first one is the default
_PROJECTORS = {
    "qtscreen": "devices.qtscreen",
}

#: rig options of a camera backend that belong to its projector: the projector's name, and what
#: is passed on to the projector backend's opener under the name it takes there
PROJECTOR_OPTIONS = {"settle": "settle", "projector_timeout": "timeout"}


@dataclass(frozen=True)
class Availability:
    """One entry of :func:`available`: a rig name and whether it can be opened here."""

    name: str
    ok: bool
    reason: str = ""

    def __str__(self) -> str:
        return f"{self.name}: {'available' if self.ok else 'unavailable'}{' — ' + self.reason if self.reason else ''}"


def _module(backend: str, table: dict[str, str] = _BACKENDS, kind: str = "rig"):
    try:
        return importlib.import_module(table[backend])
    except KeyError:
        raise InputError(f"unknown {kind} backend {backend!r}; expected one of {sorted(table)}") from None


def _default_projector() -> str:
    return next(iter(_PROJECTORS))


def _is_camera_backend(mod) -> bool:
    return not hasattr(mod, "open_rig") and hasattr(mod, "open_camera")


def available() -> list[Availability]:
    """List what can be opened on this machine, and why the rest can't.

    Returns
    -------
    list of Availability
        One entry per openable rig name (e.g. every virtual scene, every camera detected) or
        per unavailable backend (projectors: :func:`available_projectors`). A camera backend's entries are unavailable
        while the default projector cannot open (the reason says why and what to pass).
    """
    out: list[Availability] = []
    projector_problem = None
    for backend in _BACKENDS:
        try:
            mod = _module(backend)
        except ImportError as exc:  # the backend's own module failed to import
            out.append(Availability(f"{backend}:", False, f"cannot import: {exc}"))
            continue
        entries = mod.probe()
        if _is_camera_backend(mod) and any(e.ok for e in entries):
            if projector_problem is None:
                projector_problem = default_projector_problem()
            if projector_problem:
                hint = f"projector: {projector_problem} (pass projector='{_default_projector()}:0')"
                entries = [Availability(e.name, False, f"{e.reason}; {hint}" if e.reason else hint) if e.ok else e
                           for e in entries]
        out.extend(entries)
    return out


def available_projectors() -> list[Availability]:
    """List the projectors a camera's rig can use here (``projector=`` values), e.g. every screen.

    Returns
    -------
    list of Availability
        One entry per projector (``"qtscreen:1"``: the screen's name and size), or per projector
        backend that cannot be used, with the reason.
    """
    out: list[Availability] = []
    for kind, module in _PROJECTORS.items():
        try:
            out.extend(importlib.import_module(module).probe())
        except ImportError as exc:
            out.append(Availability(f"{kind}:", False, f"cannot import: {exc}"))
    return out


def default_projector_problem() -> str:
    """Why the default projector (the default backend's, e.g. a second screen) cannot open, or ``""``."""
    try:
        mod = _module(_default_projector(), _PROJECTORS, "projector")
    except ImportError as exc:
        return f"cannot import the {_default_projector()} projector: {exc}"
    return mod.default_problem()


def open_projector(spec=None, **options):
    """Open the projector a rig option names.

    Parameters
    ----------
    spec : str, Projector or None
        ``None`` (the default backend's default projector, e.g. a window on the second
        screen), ``"NAME"`` or ``"NAME:ARG"`` (``"qtscreen:HDMI-1"``, ``"qtscreen:1"``), or an
        object implementing :class:`devices.base.Projector`, returned as it is.
    **options
        The projector backend's options (``settle``, ``timeout`` for ``qtscreen``).

    Raises
    ------
    InputError
        Unknown projector backend, or options given with a Projector object.
    DeviceError
        The projector cannot be opened (no such screen, no display).

    Examples
    --------
    >>> open_projector("vga:1")
    Traceback (most recent call last):
    ...
    engine.errors.InputError: unknown projector backend 'vga'; expected one of ['qtscreen']
    """
    if spec is not None and not isinstance(spec, str):
        if options:
            raise InputError(
                f"projector options {sorted(options)} only apply to a projector opened by name, "
                f"not to the given {type(spec).__name__}"
            )
        return spec
    kind, _, arg = (spec or _default_projector()).partition(":")
    return _module(kind, _PROJECTORS, "projector").open_projector(arg or None, **options)


def pair(name: str, camera, projector=None, **projector_options):
    """Pair an open camera with a projector into a :class:`devices.base.Rig`.

    Parameters
    ----------
    name : str
        Rig name recorded in sessions, e.g. ``"opencv:0"``.
    camera : devices.base.Camera
        An open camera; closed again if the projector cannot be opened.
    projector : str, Projector or None
        See :func:`open_projector`.
    **projector_options
        Passed to :func:`open_projector`.

    Notes
    -----
    When the camera has ``mark_stale()`` and the projector ``add_shown_callback()``, the camera is
    told about each new projector frame so it drops buffers queued before the change. When the
    camera has ``set_idle(wait)`` and the projector ``idle(seconds)``, the camera waits through
    the projector, which keeps a projector window responsive while the camera blocks its thread.
    """
    try:
        proj = open_projector(projector, **projector_options)
    except BaseException:
        close = getattr(camera, "close", None)
        if close is not None:
            close()
        raise
    mark_stale = getattr(camera, "mark_stale", None)
    add_callback = getattr(proj, "add_shown_callback", None)
    if mark_stale is not None and add_callback is not None:
        add_callback(mark_stale)
    set_idle, idle = getattr(camera, "set_idle", None), getattr(proj, "idle", None)
    if set_idle is not None and idle is not None:
        set_idle(idle)
    from devices.base import Rig

    return Rig(name, camera, proj)


def open_rig(name: str, **options):
    """Open a rig by name, e.g. ``open_rig("virtual:cornell", ideal=True)``.

    Parameters
    ----------
    name : str
        ``"backend:argument"``; the argument's meaning is the backend's (a scene, a camera
        index, a session path).
    **options
        Backend options, validated by the backend. For a camera backend, ``projector=``
        (see :func:`open_projector`), ``settle=`` and ``projector_timeout=`` (seconds) choose
        and configure its projector; every other option goes to the camera.

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
    if hasattr(mod, "open_rig"):
        return mod.open_rig(arg, **options)
    if not hasattr(mod, "open_camera"):
        raise DeviceError(f"backend {backend!r} has neither a rig nor a camera opener")
    projector = options.pop("projector", None)
    popts = {theirs: options.pop(ours) for ours, theirs in PROJECTOR_OPTIONS.items() if options.get(ours) is not None}
    for ours in PROJECTOR_OPTIONS:
        options.pop(ours, None)
    camera = mod.open_camera(arg, **options)
    return pair(str(name), camera, projector, **popts)
