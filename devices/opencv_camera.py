"""UVC cameras, video files and image sequences through ``cv2.VideoCapture``, linearised.

A webcam hands over display-encoded 8-bit values; this backend turns them into linear radiance
with a response curve (supplied, or measured with :meth:`OpenCVCamera.calibrate_response`),
averages several frames to cut noise, and after each projector change drops the frames the
driver queued before it. Auto exposure and auto white balance are switched off where the
driver allows; what it refuses is recorded in :attr:`OpenCVCamera.warnings` and in every
frame's metadata.

Rig names: ``"opencv:0"`` (camera index 0), ``"opencv:/path/video.avi"``,
``"opencv:/path/frames/f_%04d.png"`` (an image sequence).
"""

from __future__ import annotations

import glob
import math
import os
import sys
import threading
from pathlib import Path

import cv2
import numpy as np

from devices._common import Watchdog
from devices._linearize import SATURATION_FRACTION, ResponseCurve, calibrate_response, response_curve
from devices.base import Frame
from devices.registry import Availability
from engine.checks import check_positive
from engine.errors import DeviceError, InputError

__all__ = ["OpenCVCamera", "open_camera", "probe"]

# CAP_PROP_AUTO_EXPOSURE value meaning "manual", and CAP_PROP_EXPOSURE units, per backend
_MANUAL_EXPOSURE = {"V4L2": 1.0, "DSHOW": 0.25, "MSMF": 0.25}


def _exposure_to_driver(backend: str, seconds: float) -> float | None:
    if backend == "V4L2":
        return seconds / 1e-4  # 100 microsecond units
    if backend in ("DSHOW", "MSMF"):
        return float(round(math.log2(seconds)))  # log2 seconds
    return None


def _exposure_from_driver(backend: str, value: float) -> float | None:
    if backend == "V4L2" and value > 0:
        return value * 1e-4
    if backend in ("DSHOW", "MSMF"):
        return 2.0**value
    return None


def _quietly_open(*args) -> cv2.VideoCapture:
    """``cv2.VideoCapture(*args)`` without OpenCV's warnings about each backend it tried.

    Opening a missing camera makes every backend OpenCV tries print a warning on stderr; the
    DeviceError raised instead says what is wrong in one line.
    """
    logging = cv2.utils.logging
    previous = logging.setLogLevel(logging.LOG_LEVEL_ERROR)
    try:
        return cv2.VideoCapture(*args)
    finally:
        logging.setLogLevel(previous)


def _parse_source(source) -> tuple[int | str, int | None, bool]:
    """Return (what to open, api preference, is_device)."""
    if isinstance(source, (int, np.integer)) and not isinstance(source, bool):
        return int(source), None, True
    text = os.fspath(source) if isinstance(source, os.PathLike) else source
    if not isinstance(text, str) or not text:
        raise InputError(f"source must be a camera index, a video file or an image-sequence pattern, got {source!r}")
    if text.strip().isdigit():
        return int(text), None, True
    if "%" in text:
        if not Path(text).parent.is_dir():
            raise DeviceError(f"the folder of image sequence {text!r} does not exist")
        return text, cv2.CAP_IMAGES, False
    if not Path(text).is_file():
        raise DeviceError(f"no such video or image file: {text!r}")
    return text, None, False


class OpenCVCamera:
    """A camera read through ``cv2.VideoCapture``, delivering linear radiance.

    Parameters
    ----------
    source : int or str
        Camera index, a video file, or an image-sequence pattern (``"dir/f_%04d.png"``, read with
        ``cv2.CAP_IMAGES``; numbering starts at 0 or 1).
    response : ResponseCurve, "srgb", "linear", float gamma, "gamma:G" or LUT, optional
        How code values map to radiance. If omitted: sRGB for 8-bit sources, linear for 16-bit
        ones, recorded as *assumed* in the metadata. Measure a webcam with
        :meth:`calibrate_response`.
    average : int
        Frames averaged (after linearisation) per capture.
    discard : int, optional
        Frames grabbed and dropped after a projector change (the driver queues some). Default:
        4 for cameras, 0 for files.
    exposure : float, optional
        Exposure in seconds. Cameras: set through the driver (auto exposure off). Files: the
        nominal exposure the frames were taken at (default 1.0).
    gain : float
        Linear gain the radiance is divided by (a recorded factor; the driver's gain control
        has no common unit and is left alone).
    timeout : float
        Seconds any single driver call may take before DeviceError.

    Attributes
    ----------
    resolution : (H, W)
    warnings : list of str
        Controls the driver refused, assumptions made.
    controls : dict
        What happened to each control at open: ``"set"``, ``"refused"`` or a value.
    """

    def __init__(
        self,
        source=0,
        *,
        response=None,
        average: int = 1,
        discard: int | None = None,
        exposure: float | None = None,
        gain: float = 1.0,
        timeout: float = 5.0,
    ):
        target, api, self.is_device = _parse_source(source)
        self.source = target
        if isinstance(average, bool) or not isinstance(average, (int, np.integer)) or average < 1:
            raise InputError(f"average must be an integer >= 1, got {average!r}")
        if discard is not None and (isinstance(discard, bool) or not isinstance(discard, (int, np.integer))
                                    or discard < 0):
            raise InputError(f"discard must be an integer >= 0, got {discard!r}")
        self.average = int(average)
        self.discard = (4 if self.is_device else 0) if discard is None else int(discard)
        self.timeout = check_positive("timeout", timeout)
        self._gain = check_positive("gain", gain)
        self.warnings: list[str] = []
        self.controls: dict[str, object] = {}
        self._lock = threading.Lock()
        self._dog = Watchdog(f"camera {target!r}")
        self._stale = self.is_device
        self.closed = False
        what = "opening the camera" if self.is_device else "opening the file"
        args = (target,) if api is None else (target, api)
        self._cap = self._dog.call(_quietly_open, *args, timeout=self.timeout, what=what)
        if not self._cap.isOpened():
            if self.is_device:
                raise DeviceError(f"no camera at index {target} (not attached, or in use by another program)")
            raise DeviceError(f"OpenCV cannot read {target!r} (unknown format or codec)")
        self.backend = self._cap.getBackendName()
        #: what a calibration depends on (engine.rig.RigLike.fingerprint)
        self.fingerprint = {"source": str(self.source), "api": self.backend}
        self._exposure = 1.0
        self._exposure_known = not self.is_device
        try:
            if self.is_device:
                self._switch_off_automatics(exposure)
            elif exposure is not None:
                self._exposure = check_positive("exposure", exposure)
            first = self._read_codes()
        except BaseException:
            self._cap.release()
            raise
        self._next: np.ndarray | None = None if self.is_device else first
        self.resolution: tuple[int, int] = first.shape[:2]
        self.dtype = first.dtype
        levels = int(np.iinfo(first.dtype).max) + 1
        self._response_note: str | None  # what the metadata calls the response when it was assumed
        if response is None:
            response = "srgb" if first.dtype == np.uint8 else "linear"
            self.warnings.append(f"response not given: assuming {response}; measure it with calibrate_response()")
            self._response_note = f"{response} (assumed)"
        else:
            self._response_note = None
        self.response = response_curve(response, levels=levels)

    # -- controls -----------------------------------------------------------------------
    def _set(self, prop: int, value: float, name: str) -> bool:
        ok = bool(self._dog.call(self._cap.set, prop, value, timeout=self.timeout, what=f"setting {name}"))
        self.controls[name] = value if ok else "refused"
        return ok

    def _switch_off_automatics(self, exposure: float | None) -> None:
        manual = _MANUAL_EXPOSURE.get(self.backend, 1.0)
        if not self._set(cv2.CAP_PROP_AUTO_EXPOSURE, manual, "auto_exposure"):
            self.warnings.append(f"the {self.backend} driver refused to switch auto exposure off: "
                                 "frames may vary in brightness")
        if not self._set(cv2.CAP_PROP_AUTO_WB, 0, "auto_wb"):
            self.warnings.append(f"the {self.backend} driver refused to switch auto white balance off")
        if exposure is not None:
            try:
                self.exposure = exposure
            except DeviceError as exc:
                self.warnings.append(str(exc))
        else:
            read = _exposure_from_driver(self.backend, float(self._cap.get(cv2.CAP_PROP_EXPOSURE)))
            if read is not None:
                self._exposure, self._exposure_known = read, True
            else:
                self.warnings.append("exposure unknown: radiance is in relative units; pass exposure= to set it")

    @property
    def exposure(self) -> float:
        """Exposure time in seconds (nominal for files)."""
        return self._exposure

    @exposure.setter
    def exposure(self, seconds: float) -> None:
        seconds = check_positive("exposure", seconds)
        if not self.is_device:
            if seconds != self._exposure:  # the frames were taken at one exposure: never pretend otherwise
                raise InputError(
                    f"the exposure of a file source is fixed at {self._exposure:g} s (asked for {seconds:g} s); "
                    "pass exposure= when opening it"
                )
            return
        value = _exposure_to_driver(self.backend, seconds)
        if value is None:
            raise DeviceError(f"OpenCV's {self.backend} backend has no known exposure unit; cannot set exposure")
        if not self._set(cv2.CAP_PROP_EXPOSURE, value, "exposure"):
            raise DeviceError(f"the {self.backend} driver refused exposure {seconds:g} s (value {value:g}); "
                              "is auto exposure still on?")
        self._exposure, self._exposure_known = seconds, True
        self._stale = True

    @property
    def gain(self) -> float:
        """Linear gain the radiance is divided by."""
        return self._gain

    @gain.setter
    def gain(self, value: float) -> None:
        self._gain = check_positive("gain", value)

    def mark_stale(self) -> None:
        """The scene changed (a new projector frame): drop queued frames before the next capture."""
        self._stale = True

    # -- reading ------------------------------------------------------------------------
    def _read_codes(self) -> np.ndarray:
        ok, frame = self._dog.call(self._cap.read, timeout=self.timeout, what="reading a frame")
        if not ok or frame is None:
            if self.is_device:
                raise DeviceError(f"camera {self.source} stopped delivering frames "
                                  "(unplugged, or in use by another program?)")
            raise DeviceError(f"no more frames in {self.source!r}")
        if frame.dtype not in (np.uint8, np.uint16):
            raise DeviceError(f"{self.source!r} delivered {frame.dtype} frames; expected 8- or 16-bit")
        if frame.ndim == 2:
            frame = np.repeat(frame[:, :, None], 3, axis=2)
        elif frame.shape[2] == 4:
            frame = frame[:, :, :3]
        elif frame.shape[2] == 1:
            frame = np.repeat(frame, 3, axis=2)
        rgb = np.ascontiguousarray(frame[:, :, ::-1])  # OpenCV delivers BGR
        size = getattr(self, "resolution", None)
        if size is not None and rgb.shape[:2] != tuple(size):
            raise DeviceError(f"{self.source!r} delivered a {rgb.shape[1]}x{rgb.shape[0]} frame; "
                              f"the camera is {size[1]}x{size[0]}")
        return rgb

    def capture_codes(self) -> np.ndarray:
        """One frame's raw code values, (H, W, 3) uint8/uint16 RGB, after dropping stale frames."""
        with self._lock:
            self._check_open()
            return self._next_codes()

    def _next_codes(self) -> np.ndarray:
        if self._stale and self.discard:
            for _ in range(self.discard):
                self._dog.call(self._cap.grab, timeout=self.timeout, what="dropping a queued frame")
        self._stale = False
        if self._next is not None:
            codes, self._next = self._next, None
            return codes
        return self._read_codes()

    def _check_open(self) -> None:
        if self.closed:
            raise DeviceError(f"camera {self.source!r} is closed")

    def capture(self) -> Frame:
        """Average ``average`` linearised frames into one Frame of linear radiance.

        Returns
        -------
        Frame
            ``image`` = mean of response(codes) / (exposure * gain), float32 (H, W, 3);
            ``saturated`` where any channel of any averaged frame reached 254/255 of full scale.

        Raises
        ------
        DeviceError
            No more frames, the camera stopped answering, or a frame of another size.
        """
        with self._lock:
            self._check_open()
            total = np.zeros((*self.resolution, 3), np.float64)
            saturated = np.zeros(self.resolution, bool)
            threshold = None
            for _ in range(self.average):
                codes = self._next_codes()
                if threshold is None:
                    threshold = math.ceil(SATURATION_FRACTION * np.iinfo(codes.dtype).max)
                saturated |= np.any(codes >= threshold, axis=2)
                total += self.response.apply(codes)
            image = (total / (self.average * self._exposure * self._gain)).astype(np.float32)
            meta = {
                "backend": "opencv",
                "driver": self.backend,
                "source": self.source if isinstance(self.source, int) else str(self.source),
                "response": self._response_note or self.response.name,
                "averaged": self.average,
                "exposure_known": self._exposure_known,
                "controls": dict(self.controls),
                "warnings": list(self.warnings),
            }
            return Frame(image=image, exposure=self._exposure, gain=self._gain, black_level=0.0, saturated=saturated,
                         metadata=meta)

    def calibrate_response(self, exposures, *, samples: int = 70, smoothness: float = 10.0) -> ResponseCurve:
        """Measure this camera's response from a bracket of exposures of a static scene.

        Sets each exposure, captures (averaging ``average`` frames in code space), runs
        :func:`devices._linearize.calibrate_response` (OpenCV Debevec), makes the result this
        camera's :attr:`response`, and restores the previous exposure.

        Parameters
        ----------
        exposures : sequence of float
            Exposure times in seconds, ideally spanning 8+ stops.

        Raises
        ------
        DeviceError
            The source is a file or the driver refuses exposure changes.
        """
        if not self.is_device:
            raise DeviceError("a file's exposure cannot be changed; calibrate a response from a bracketed set "
                              "with devices._linearize.calibrate_response")
        if self.dtype != np.uint8:
            raise DeviceError("Debevec calibration needs 8-bit frames; this camera delivers 16-bit")
        before = self._exposure
        images = []
        try:
            for t in exposures:
                self.exposure = t
                stack = [self.capture_codes().astype(np.float64) for _ in range(self.average)]
                images.append(np.rint(np.mean(stack, axis=0)).astype(np.uint8))
        finally:
            self.exposure = before
        self.response = calibrate_response(images, exposures, samples=samples, smoothness=smoothness)
        self._response_note = None
        return self.response

    def close(self) -> None:
        """Release the device or file. Idempotent."""
        if self.closed:
            return
        self.closed = True
        with self._lock:
            try:
                self._dog.call(self._cap.release, timeout=self.timeout, what="releasing the camera")
            except DeviceError:
                pass

    def __repr__(self) -> str:
        return f"OpenCVCamera({self.source!r}, resolution={self.resolution}, response={self.response.name!r})"


def open_camera(arg="", **options) -> OpenCVCamera:
    """Open ``"opencv:ARG"``: an :class:`OpenCVCamera` on a camera index (default 0), a video file or an
    image-sequence pattern (:func:`devices.open_rig` pairs it with a projector)."""
    return OpenCVCamera(arg if arg not in ("", None) else 0, **options)


def _video_devices() -> list[int]:
    if sys.platform.startswith("linux"):
        found = []
        for dev in sorted(glob.glob("/dev/video*")):
            tail = dev[len("/dev/video") :]
            if tail.isdigit():
                found.append(int(tail))
        return found
    return [0]  # other systems have no cheap listing: offer index 0


def probe() -> list[Availability]:
    """Cameras OpenCV may open (``/dev/video*`` on Linux), and files."""
    out = [Availability(f"opencv:{i}", True, f"video device {i}") for i in _video_devices()]
    if not out:
        out.append(Availability("opencv:0", False, "no camera attached (no /dev/video* device)"))
    out.append(Availability("opencv:FILE", True, "a video file or image sequence such as opencv:frames/f_%04d.png"))
    return out
