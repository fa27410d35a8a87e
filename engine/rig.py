"""What the engine needs from a camera–projector rig: the protocols every backend implements.

The engine consumes these (:class:`engine.acquire.Recorder` is the only place acquisition
touches a rig); ``devices/`` implements them and re-exports them from ``devices.base``. Nothing
here knows a vendor API.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Camera", "Frame", "Projector", "RigLike"]


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
        lower bound. Default: none.
    metadata : dict
        Backend-specific facts (device name, raw file name, settle time, frames averaged,
        exposure brackets, ...), JSON-serialisable.
    """

    image: np.ndarray
    exposure: float
    gain: float = 1.0
    black_level: float = 0.0
    saturated: np.ndarray = None  # type: ignore[assignment]  # filled in __post_init__
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.saturated is None:
            object.__setattr__(self, "saturated", np.zeros(np.shape(self.image)[:2], dtype=bool))


@runtime_checkable
class Camera(Protocol):
    """A linear camera.

    Attributes
    ----------
    resolution : (int, int)
        ``(H, W)`` of every frame.
    exposure : float
        Exposure time in seconds; settable (a camera that cannot change it raises
        ``ValueError`` or :class:`engine.errors.DeviceError` on assignment).
    gain : float
        Linear gain; settable likewise.
    """

    resolution: tuple[int, int]
    exposure: float
    gain: float

    def capture(self) -> Frame:
        """Take one frame of whatever the projector shows now."""
        ...


@runtime_checkable
class Projector(Protocol):
    """A projector.

    Attributes
    ----------
    resolution : (int, int)
        ``(Hp, Wp)`` of every pattern.
    bit_depth : int
        Bits per channel of the projector's input (8 for almost every projector).
    """

    resolution: tuple[int, int]
    bit_depth: int

    def show(self, image: np.ndarray) -> None:
        """Display float32 ``(Hp, Wp, 3)`` in [0, 1] (already through the inverse response).

        Returns once the frame is on the wall (plus any settle time).
        """
        ...


class RigLike(Protocol):
    """A calibrated pair: one camera and one projector.

    Attributes
    ----------
    name : str
        The name it was opened by (``"virtual:cornell"``).
    identity : str
        The physical set-up this rig stands for, which calibrations are checked against.
    camera : Camera
    projector : Projector
    """

    name: str
    identity: str
    camera: Camera
    projector: Projector
