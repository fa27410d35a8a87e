"""What the engine needs from a camera–projector rig: the protocols every backend implements.

The engine consumes these (:class:`engine.acquire.Recorder` is the only place acquisition
touches a rig); ``devices/`` implements them and re-exports them from ``devices.base``. Nothing
here knows a vendor API.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Camera", "Frame", "Projector", "RigLike", "fingerprint_differences", "fingerprint_of"]


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
    full_scale : float or None
        Radiance at which this frame clips (the sensor's full well or white level, in the units
        of ``image`` at this exposure and gain), when the backend knows it; ``math.inf`` for a
        camera that does not clip at all (an ideal simulated sensor). Exposure control judges
        the bright end against it instead of waiting for pixels to clip.
    variance : (H, W, 3) float32 or None
        Variance of ``image`` that the camera's noise model (``metadata["noise"]``, the
        calibration's) does not describe, per pixel and channel in ``image``'s units squared,
        when the backend estimates it: a path tracer's Monte Carlo noise (the ``mitsuba:`` rig,
        from the difference of two half-sample renders). :class:`engine.acquire.Recorder`
        adds it to the model's variance. Not stored in a session: a capture read back from one
        carries the model's variance only. Default: none.
    """

    image: np.ndarray
    exposure: float
    gain: float = 1.0
    black_level: float = 0.0
    saturated: np.ndarray = None  # type: ignore[assignment]  # filled in __post_init__
    metadata: dict[str, Any] = field(default_factory=dict)
    full_scale: float | None = None
    variance: np.ndarray | None = None

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
    frame_identity : str or None, optional
        Only for simulated cameras: set by :class:`engine.acquire.Recorder` before each frame
        to the frame's identity (capture name, pattern, frame index), from which the camera
        seeds that frame's noise (with its own seed) — never from the process, so no two
        frames share their noise and a resumed run reproduces an uninterrupted one. A real
        camera has no such attribute.
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
    fingerprint : dict
        Everything a calibration of this rig depends on, as named plain values: backend,
        device model and serial, resolutions, projector pose or screen, ideal or realistic,
        scene content for a simulated rig. A calibration made with another fingerprint is
        refused (:func:`fingerprint_differences` says what differs). Optional: without it,
        :func:`fingerprint_of` uses the identity and the resolutions.
    camera : Camera
    projector : Projector
    """

    name: str
    identity: str
    camera: Camera
    projector: Projector


def fingerprint_of(rig) -> dict:
    """The rig's :attr:`RigLike.fingerprint`, or its identity and resolutions when it has none.

    Examples
    --------
    >>> class Bare:
    ...     identity = "opencv:0"
    ...     class camera: resolution = (480, 640)
    ...     class projector: resolution = (768, 1024)
    >>> fingerprint_of(Bare())
    {'rig': 'opencv:0', 'camera resolution': [480, 640], 'projector resolution': [768, 1024]}
    """
    given = getattr(rig, "fingerprint", None)
    if isinstance(given, dict):
        return dict(given)
    return {"rig": str(rig.identity), "camera resolution": [int(v) for v in rig.camera.resolution],
            "projector resolution": [int(v) for v in rig.projector.resolution]}


def fingerprint_differences(made_with: dict, now: dict) -> list[str]:
    """What differs between two rig fingerprints, one phrase per entry (empty: the same set-up).

    Examples
    --------
    >>> fingerprint_differences({"projector pose": "coaxial", "ideal": True},
    ...                         {"projector pose": "offset", "ideal": True})
    ["projector pose 'coaxial' then, 'offset' now"]
    """
    out = []
    for key in sorted(set(made_with) | set(now)):
        then, current = made_with.get(key), now.get(key)
        if then != current:
            out.append(f"{key} {then!r} then, {current!r} now")
    return out
