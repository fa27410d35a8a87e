"""The device protocols every backend implements, and the :class:`Rig` that pairs them.

Nothing outside ``devices/`` knows a vendor API: acquisition and calibration talk only to
these protocols.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class Frame:
    """One capture: linear radiance plus how it was taken.

    Attributes
    ----------
    image : (H, W, 3) float32
        Linear radiance, black level removed and divided by exposure and gain, so two frames
        of the same light at different exposures agree. Never gamma-encoded.
    exposure : float
        Exposure time in seconds.
    gain : float
        Linear sensor gain (ISO / base ISO).
    black_level : float
        Black level removed from the raw values, in raw units.
    saturated : (H, W) bool
        Pixels where any channel reached the sensor's clipping level; their radiance is a
        lower bound.
    metadata : dict
        Backend-specific facts (device name, raw file name, settle time, ...), JSON-serialisable.
    """

    image: np.ndarray
    exposure: float
    gain: float = 1.0
    black_level: float = 0.0
    saturated: np.ndarray | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.saturated is None:
            object.__setattr__(self, "saturated", np.zeros(self.image.shape[:2], dtype=bool))


@runtime_checkable
class Camera(Protocol):
    """A linear camera. ``resolution`` is ``(H, W)``; exposure in seconds, gain linear."""

    resolution: tuple[int, int]
    exposure: float
    gain: float

    def capture(self) -> Frame:
        """Take one frame of whatever the projector shows now."""
        ...


@runtime_checkable
class Projector(Protocol):
    """A projector. ``show`` takes float32 ``(Hp, Wp, 3)`` in [0, 1], already passed through
    the inverse response, and returns once the frame is on the wall."""

    resolution: tuple[int, int]
    bit_depth: int

    def show(self, image: np.ndarray) -> None:
        """Display ``image`` and return once it is shown (plus any settle time)."""
        ...


class Rig:
    """One camera and one projector, used as a context manager that leaves hardware safe.

    Parameters
    ----------
    name : str
        The name it was opened by, e.g. ``"virtual:cornell"``; recorded in sessions.
    camera, projector
        The two devices.
    targets : dict[str, (H, W) bool], optional
        Named target masks the rig knows (the virtual rig's scene targets).
    truth : object, optional
        Ground truth (virtual rig only).
    identity : str, optional
        The physical rig this one stands for, which calibrations are checked against
        (default: ``name``; a ``replay:`` rig stands for the rig it recorded).
    """

    def __init__(self, name: str, camera: Camera, projector: Projector, *, targets=None, truth=None, identity=None):
        self.name = name
        self.identity = identity or name
        self.camera = camera
        self.projector = projector
        self.targets: dict[str, np.ndarray] = dict(targets or {})
        self.truth = truth
        self.closed = False

    def blank(self) -> None:
        """Show black on the projector (the safe state)."""
        hp, wp = self.projector.resolution
        self.projector.show(np.zeros((hp, wp, 3), np.float32))

    def close(self) -> None:
        """Leave the hardware safe: projector black, devices released. Idempotent."""
        if self.closed:
            return
        self.closed = True
        try:
            self.blank()
        finally:
            for dev in (self.projector, self.camera):
                close = getattr(dev, "close", None)
                if close is not None:
                    close()

    def __enter__(self) -> "Rig":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Rig({self.name!r}, camera={self.camera.resolution}, projector={self.projector.resolution})"
