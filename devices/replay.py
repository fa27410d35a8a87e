"""The ``replay`` backend: serve a recorded session's captures back, pattern by pattern.

``open_rig("replay:/path/to/session")`` gives a rig whose projector remembers the last pattern
shown (its :func:`engine.session.pattern_hash`) and whose camera returns the capture recorded
under that pattern. Running the same acquisition against it reproduces the recorded one
offline, byte for byte, and a pattern the recording never showed is a clear
:class:`~engine.errors.DeviceError` instead of a made-up frame.

Which recording is served when a pattern was captured several times (a black frame taken at
the start and again at the end, or bracketed exposures):

- if the camera's exposure was set, only records whose ``meta["exposure"]`` equals it (to a
  relative 1e-6) are candidates; otherwise all records of the pattern are;
- the n-th ``capture()`` of the same (pattern, exposure) returns the n-th candidate in the
  log's order, and the last one again once they are used up.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from devices.base import Frame, Rig
from devices.registry import Availability
from engine.errors import DeviceError, InputError, SessionError
from engine.session import CaptureRecord, Session, pattern_hash

__all__ = ["ReplayCamera", "ReplayProjector", "open_rig", "probe"]


class ReplayProjector:
    """A projector that records which pattern is on the (imaginary) wall.

    Attributes
    ----------
    resolution : (int, int)
        ``(Hp, Wp)`` of the recorded projector.
    bit_depth : int
        From the session's metadata ``projector_bit_depth`` (default 8).
    pattern_id : str or None
        :func:`engine.session.pattern_hash` of the last pattern shown (None before the first).
    """

    def __init__(self, resolution: tuple[int, int], bit_depth: int = 8):
        h, w = resolution
        self.resolution = (h, w)
        self.bit_depth = int(bit_depth)
        self.pattern_id: str | None = None

    def show(self, image: np.ndarray) -> None:
        """Remember ``image`` (float32 ``(Hp, Wp, 3)`` in [0, 1]) as the current pattern.

        Raises
        ------
        InputError
            Wrong shape, not float, non-finite or outside [0, 1].
        """
        array = np.asarray(image)
        hp, wp = self.resolution
        if array.shape != (hp, wp, 3):
            raise InputError(f"image must have shape {(hp, wp, 3)} (projector pixels, RGB), got {array.shape}")
        if array.dtype.kind != "f":
            raise InputError(f"image must be float32 projector values in [0, 1], got dtype {array.dtype}")
        if not np.all(np.isfinite(array)) or array.min() < 0.0 or array.max() > 1.0:
            raise InputError(
                f"image must be finite and in [0, 1], got range [{np.nanmin(array):g}, {np.nanmax(array):g}]"
            )
        self.pattern_id = pattern_hash(array)


class ReplayCamera:
    """A camera that returns, for the pattern on the projector, the frame recorded under it.

    Attributes
    ----------
    resolution : (int, int)
        ``(H, W)`` of the recorded camera.
    exposure : float
        Seconds. Reading it before setting it gives the first capture's exposure; setting it
        restricts replay to records taken at that exposure.
    gain : float
        Recorded with frames only (replay cannot change the light).
    """

    def __init__(self, session: Session, projector: ReplayProjector):
        self.resolution = session.camera_resolution
        self._session = session
        self._projector = projector
        first = session.captures[0].meta if session.captures else {}
        self._exposure = float(first.get("exposure", 1.0))
        self._exposure_set = False
        self.gain = float(first.get("gain", 1.0))
        self._served: dict[tuple[str, float | None], int] = {}

    @property
    def exposure(self) -> float:
        return self._exposure

    @exposure.setter
    def exposure(self, value: float) -> None:
        value = float(value)
        if not math.isfinite(value) or value <= 0:
            raise InputError(f"exposure must be a positive number of seconds, got {value!r}")
        self._exposure = value
        self._exposure_set = True

    def _candidates(self, pattern_id: str) -> list[CaptureRecord]:
        records = self._session.find_by_pattern(pattern_id)
        if not records:
            raise DeviceError(
                f"pattern {pattern_id} was never recorded: session {self._session.path} has no capture for it"
            )
        if not self._exposure_set:
            return records
        matching = [
            r
            for r in records
            if isinstance(r.meta.get("exposure"), (int, float))
            and math.isclose(float(r.meta["exposure"]), self._exposure, rel_tol=1e-6)
        ]
        if not matching:
            recorded = sorted({r.meta.get("exposure") for r in records}, key=str)
            raise DeviceError(
                f"pattern {pattern_id} was recorded in session {self._session.path} only at exposures {recorded}, "
                f"not at {self._exposure:g} s"
            )
        return matching

    def capture(self) -> Frame:
        """Return the recorded frame for the projector's current pattern (a fresh copy).

        Raises
        ------
        DeviceError
            Nothing shown yet, the pattern was never recorded (the message names its hash),
            or the capture file can't be read.
        """
        pattern_id = self._projector.pattern_id
        if pattern_id is None:
            raise DeviceError("replay camera: nothing has been shown on the projector yet, "
                              "so there is nothing to replay")
        records = self._candidates(pattern_id)
        slot = (pattern_id, self._exposure if self._exposure_set else None)
        n = self._served.get(slot, 0)
        record = records[min(n, len(records) - 1)]
        try:
            loaded = self._session.load_capture(record.name)
        except SessionError as exc:
            raise DeviceError(f"replay camera: {exc}") from exc
        self._served[slot] = n + 1
        meta = record.meta
        metadata = dict(meta.get("metadata") or {}) if isinstance(meta.get("metadata"), dict) else {}
        metadata["replay"] = {"session": str(self._session.path), "capture": record.name, "pattern_id": pattern_id}
        return Frame(
            image=loaded.image,
            exposure=float(meta.get("exposure", self._exposure)),
            gain=float(meta.get("gain", 1.0)),
            black_level=float(meta.get("black_level", 0.0)),
            saturated=loaded.saturated,
            metadata=metadata,
        )


def open_rig(arg: str, **options) -> Rig:
    """Open ``"replay:PATH"``: a rig serving the captures of the session folder ``PATH``.

    Parameters
    ----------
    arg : str
        The session folder.
    **options
        None are accepted.

    Returns
    -------
    devices.base.Rig
        Named ``"replay:PATH"``; resolutions from the session; ``targets`` are the session's
        masks.

    Raises
    ------
    InputError
        No path given, or options given.
    DeviceError
        The session can't be opened (the message says why).
    """
    if options:
        raise InputError(f"the replay backend takes no options, got {sorted(options)}")
    if not arg:
        raise InputError("replay needs a session folder: open_rig('replay:/path/to/session')")
    try:
        session = Session.open(Path(arg))
        targets = {name: session.read_mask(name) for name in session.masks}
    except SessionError as exc:
        raise DeviceError(f"cannot replay {arg}: {exc}") from exc
    bit_depth = session.metadata.get("projector_bit_depth", 8)
    projector = ReplayProjector(session.projector_resolution, bit_depth if isinstance(bit_depth, int) else 8)
    camera = ReplayCamera(session, projector)
    return Rig(f"replay:{arg}", camera, projector, targets=targets, identity=session.rig_name,
               fingerprint=session.fingerprint)


def probe() -> list[Availability]:
    """Replay needs no hardware; it needs a session folder, given in the name.

    Examples
    --------
    >>> print(probe()[0])
    replay:PATH: available — give a session folder
    """
    return [Availability("replay:PATH", True, "give a session folder")]
