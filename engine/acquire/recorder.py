"""Showing a pattern and capturing it, once: the only place acquisition touches a rig.

Every capture has a name that is a pure function of the plan (``"r2-g"``, ``"gray-017"``).
With a session, a capture already on disk is read back instead of taken again, after
checking that it was taken with the same pattern: re-running an interrupted plan on the same
session therefore resumes it exactly where it stopped.

Frames with clipped pixels (a lamp in view, a specular highlight) are completed from shorter
exposures when the camera's exposure can be set: frames are linear radiance, so a pixel's
value does not depend on the exposure it was read at.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from engine.errors import DeviceError, DiskFull, SessionError
from engine.noise import CameraNoise, frame_variance
from engine.progress import Progress, ShouldStop, checkpoint, report
from engine.rig import Frame, RigLike
from engine.session import Session, pattern_hash
from engine.session.space import megabytes


@dataclass
class Recorder:
    """Take named captures through a rig, persisting them in an optional session.

    Parameters
    ----------
    rig : engine.rig.RigLike
        A camera and a projector (the protocols of :mod:`engine.rig`, implemented by
        ``devices``; the engine does not import ``devices``).
    session : Session, optional
        Where captures are written the moment they arrive, and read back on resume.
    progress : callable, optional
        ``progress(step, total, message)``; ``total`` is :attr:`planned` as last set.
    should_stop : callable, optional
        Checked before every capture; a stop raises :class:`engine.errors.Cancelled` and
        loses nothing already captured.
    on_capture : callable, optional
        ``on_capture(name, image)`` after each capture (e.g. thumbnails in the app).
    frames : int
        Frames averaged per capture (noise falls as 1/sqrt(frames); the method amplifies
        noise by κ^i at order i, so large κ wants more).
    brackets : int
        Up to this many shorter exposures (each ``bracket_step`` times shorter) complete the
        saturated pixels of a frame; 0 keeps clipped frames as they are.
    bracket_step : float
    noise : CameraNoise, optional
        The camera's noise as the calibration measured it, for frames whose backend does
        not report its own (``Frame.metadata["noise"]``).

    Attributes
    ----------
    taken, reused : list of str
        Names captured now, and names read back from the session.
    planned : int
        Number of captures the current plan expects (for progress).
    last_saturated : (H, W) bool or None
        Clipped pixels of the last capture (after bracketing), None if unknown.
    last_variance : (H, W, 3) float32 or None
        Variance of the last capture (:func:`engine.noise.frame_variance`, plus the frame's own
        :attr:`engine.rig.Frame.variance` when it reports one), None when neither the frame nor
        :attr:`noise` knows the camera's noise.
    """

    rig: RigLike
    session: Session | None = None
    progress: Progress | None = None
    should_stop: ShouldStop | None = None
    on_capture: Callable[[str, np.ndarray], object] | None = None
    frames: int = 1
    brackets: int = 3
    bracket_step: float = 8.0
    noise: CameraNoise | None = None
    taken: list[str] = field(default_factory=list)
    reused: list[str] = field(default_factory=list)
    planned: int = 0
    last_saturated: np.ndarray | None = None
    last_variance: np.ndarray | None = None

    @property
    def count(self) -> int:
        """Captures obtained so far (taken now or reused)."""
        return len(self.taken) + len(self.reused)

    def capture(self, name: str, pattern: np.ndarray, *, meta: dict | None = None) -> np.ndarray:
        """Show ``pattern`` and capture, or reuse the session's capture ``name``.

        Parameters
        ----------
        name : str
            Stable name of this capture within the plan.
        pattern : (Hp, Wp, 3) float32
            Projector image in [0, 1] (already through the inverse response).
        meta : dict, optional
            JSON facts stored with the capture (step, channel, scale, ...).

        Returns
        -------
        (H, W, 3) float32
            Linear radiance.

        Raises
        ------
        SessionError
            The session has a capture of that name taken with a different pattern (the plan
            changed since: start a new session).
        Cancelled
            ``should_stop()`` returned True before the capture.
        """
        pid = pattern_hash(pattern)
        if self.session is not None and self.session.has_capture(name):
            record = self.session.capture_record(name)
            if record.pattern_id != pid:
                raise SessionError(
                    f"capture {name!r} in {self.session.path} was taken with a different projector pattern; "
                    "the acquisition settings changed since: use a new session folder"
                )
            loaded = self.session.load_capture(name)
            image, self.last_saturated = loaded.image, loaded.saturated
            meta = record.meta
            self.last_variance = frame_variance(image, float(meta.get("exposure", 1.0) or 1.0), meta.get("metadata"),
                                                self.noise)
            self.reused.append(name)
        else:
            checkpoint(self.should_stop, "acquisition")
            report(self.progress, self.count, self.planned, f"capturing {name}")
            self.rig.projector.show(pattern)
            identity = f"{name}|{pid}"
            frame = self._bracketed(self._shot(identity), identity)
            image = np.asarray(frame.image, np.float32)
            self.last_saturated = np.asarray(frame.saturated, bool)
            self.last_variance = _with_own_variance(
                frame_variance(image, float(frame.exposure), getattr(frame, "metadata", None), self.noise), frame)
            if self.session is not None:
                try:
                    self.session.add_frame(name, frame, pattern_id=pid, meta=meta or {})
                except DiskFull as exc:
                    left = max(self.planned - self.count, 1)
                    raise DiskFull(f"{exc} (this run has {left} captures left to store: about "
                                   f"{megabytes(left * exc.needed)} in all)", free=exc.free,
                                   needed=left * exc.needed) from exc
            self.taken.append(name)
        if self.on_capture is not None:
            self.on_capture(name, image)
        report(self.progress, self.count, max(self.planned, self.count), f"captured {name}")
        return image

    def _frame(self, identity: str):
        """One frame from the camera; a simulated camera seeds its noise from the frame's ``identity``."""
        camera = self.rig.camera
        if hasattr(camera, "frame_identity"):
            camera.frame_identity = identity
        return camera.capture()

    def _shot(self, identity: str):
        """One frame, or the mean of ``frames`` frames (saturated where any was).

        ``identity`` names the capture and its pattern; each frame adds its index, so no two
        frames of a plan share their noise and a resumed run takes the frames an
        uninterrupted one would have.
        """
        if self.frames <= 1:
            return self._frame(f"{identity}|0")
        shots = [self._frame(f"{identity}|{i}") for i in range(self.frames)]
        first = shots[0]
        image = np.stack([np.asarray(f.image, np.float32) for f in shots]).mean(axis=0, dtype=np.float64)
        image = image.astype(np.float32)
        saturated = np.logical_or.reduce([np.asarray(f.saturated, bool) for f in shots])
        meta = dict(getattr(first, "metadata", {}) or {})
        meta["frames"] = self.frames
        own = [v for v in (getattr(f, "variance", None) for f in shots) if v is not None]
        variance = None
        if len(own) == len(shots):  # of the mean: Σ var / n²
            variance = np.asarray(np.sum(np.stack(own), axis=0, dtype=np.float64) / self.frames**2, np.float32)
        return Frame(image, first.exposure, getattr(first, "gain", 1.0), getattr(first, "black_level", 0.0),
                     saturated, meta, variance=variance)

    def _bracketed(self, frame, identity: str):
        """Complete the frame's saturated pixels from shorter exposures (same projector image)."""
        saturated = np.asarray(frame.saturated, bool)
        camera = self.rig.camera
        if self.brackets <= 0 or not saturated.any():
            return frame
        image = np.array(frame.image, np.float32)
        own = getattr(frame, "variance", None)
        variance = None if own is None else np.array(own, np.float32)
        start = camera.exposure
        used = []
        refused = None
        try:
            for step in range(1, self.brackets + 1):
                try:
                    camera.exposure = camera.exposure / self.bracket_step
                except (AttributeError, ValueError, TypeError, DeviceError) as exc:
                    refused = str(exc)  # this camera cannot change exposure: keep what we have
                    break
                short = self._shot(f"{identity}|bracket{step}")  # a failing capture is a device fault: it propagates
                fix = saturated & ~np.asarray(short.saturated, bool)
                image[fix] = short.image[fix]
                if variance is not None:
                    short_own = getattr(short, "variance", None)
                    if short_own is None:
                        variance = None  # the completed pixels' own variance is unknown
                    else:
                        variance[fix] = np.asarray(short_own, np.float32)[fix]
                saturated = saturated & np.asarray(short.saturated, bool)
                used.append(float(camera.exposure))
                if not saturated.any():
                    break
        finally:
            if camera.exposure != start:
                camera.exposure = start
        meta = dict(getattr(frame, "metadata", {}) or {})
        meta["brackets"] = used
        if refused is not None:
            meta["bracketing_refused"] = refused
        return Frame(image, frame.exposure, getattr(frame, "gain", 1.0), getattr(frame, "black_level", 0.0),
                     saturated, meta, variance=variance)

    def black(self) -> np.ndarray:
        """A black projector image of the rig's projector resolution."""
        hp, wp = self.rig.projector.resolution
        return np.zeros((hp, wp, 3), np.float32)


def _with_own_variance(variance: np.ndarray | None, frame) -> np.ndarray | None:
    """The model's ``variance`` of a frame plus the variance the frame reports itself (:attr:`Frame.variance`).

    None stays None: without a noise model for the camera no covariance is tracked at all.
    """
    own = getattr(frame, "variance", None)
    if variance is None or own is None:
        return variance
    return (variance + np.asarray(own, np.float32)).astype(np.float32)
