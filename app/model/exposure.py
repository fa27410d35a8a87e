"""The calibration wizard's exposure logic without Qt: live frames, their verdict, auto exposure.

The exposure page's live loop asks :meth:`ExposureController.request` what to apply (camera
exposure, projector level), grabs a frame on a worker, judges it there with :func:`judge`, and
hands the :class:`LiveFrame` back to :meth:`ExposureController.on_frame` on the UI thread. Auto
exposure is a short sequence of those frames: one under projector black (what ambient light
lights: a lamp in view), then under white until the brightest projector-lit pixels sit at
``headroom`` of the camera's full scale (:class:`engine.calibrate.AutoExposure`) — in one jump
when the frames say where the camera clips, at once for a camera that does not clip, and never
more than :attr:`ExposureController.max_frames` frames.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from engine.calibrate import AutoExposure, exposure_report, projector_lit

#: Projector levels of the live view, in the order the page lists them.
LEVELS = ("white", "black", "identify")


@dataclass
class LiveFrame:
    """One live frame as grabbed and judged on the worker.

    ``asked`` is the exposure the grab applied (None: left as it was); ``exposure`` the one
    the camera reports it used (a camera may round). ``lit`` marks the projector-lit pixels
    once a black frame is known; ``report``/``ok`` are the verdict in words.
    """

    image: np.ndarray
    saturated: np.ndarray
    exposure: float
    gain: float
    full_scale: float | None
    level: str
    asked: float | None
    lit: np.ndarray | None
    report: str
    ok: bool
    thread: str = ""


def judge(frame, level: str, asked: float | None, black: np.ndarray | None) -> LiveFrame:
    """Judge a camera ``frame`` taken under projector ``level`` (worker side; pure).

    With ``black`` (a frame under projector black) and the white level, only projector-lit
    pixels are judged: what calibration measures is projector light, and a lamp may clip.
    """
    image = np.asarray(frame.image, np.float32)
    lit = projector_lit(image, black) if black is not None and level == "white" else None
    full_scale = getattr(frame, "full_scale", None)
    report = exposure_report(image, saturated=frame.saturated, target=lit, full_scale=full_scale,
                             label=None if lit is None else "projector-lit pixels")
    return LiveFrame(image, np.asarray(frame.saturated, bool), float(frame.exposure),
                     float(getattr(frame, "gain", 1.0)), full_scale, level, asked, lit, report.message, report.ok,
                     threading.current_thread().name)


class ExposureController:
    """What the live loop applies and what auto exposure does next.

    Parameters
    ----------
    exposure : float or None
        The camera's exposure in seconds (None: this camera's exposure cannot be set).
    max_frames : int
        Auto exposure gives up after this many frames under white (a camera that never clips
        and never says where it would).
    headroom, percentile, max_saturated
        See :class:`engine.calibrate.AutoExposure`.

    Examples
    --------
    >>> from types import SimpleNamespace as F
    >>> c = ExposureController(exposure=0.01)
    >>> c.start_auto()  # "" : it runs
    ''
    >>> c.request()
    (0.01, 'black')
    >>> img = np.full((4, 4, 3), 2.0, np.float32); sat = np.zeros((4, 4), bool)
    >>> c.on_frame(judge(F(image=img * 0, saturated=sat, exposure=0.01, full_scale=10.0), "black", 0.01, None))
    >>> c.request()
    (0.01, 'white')
    >>> c.on_frame(judge(F(image=img, saturated=sat, exposure=0.01, full_scale=10.0), "white", 0.01, c.black))
    >>> [round(v, 4) if isinstance(v, float) else v for v in c.request()]  # 2.0 → 0.8 × full scale
    [0.04, 'white']
    """

    def __init__(self, *, exposure: float | None, max_frames: int = 10, headroom: float = 0.8,
                 percentile: float = 99.5, max_saturated: float = 0.005):
        self.exposure = None if exposure is None else float(exposure)
        self.level = LEVELS[0]
        self.max_frames = int(max_frames)
        self._auto_args = {"headroom": headroom, "percentile": percentile, "max_saturated": max_saturated}
        self.auto: AutoExposure | None = None
        self.black: np.ndarray | None = None
        self.frames = 0
        self.message = ""

    @property
    def running(self) -> bool:
        """Whether auto exposure is under way."""
        return self.auto is not None

    def request(self) -> tuple[float | None, str]:
        """(exposure in seconds or None, projector level) the next grab applies."""
        return self.exposure, self.level

    def set_exposure(self, seconds: float) -> None:
        """The user set the exposure (stops auto exposure)."""
        if self.exposure is not None:
            self.exposure = float(seconds)
            self._stop("")

    def set_level(self, level: str) -> None:
        """The user chose a projector level (stops auto exposure)."""
        if level not in LEVELS:
            raise ValueError(f"level must be one of {LEVELS}, got {level!r}")
        if level != self.level:
            self.level = level
            self._stop("")

    def start_auto(self) -> str:
        """Start auto exposure; returns why it cannot run ("" when it runs)."""
        if self.exposure is None:
            return "This camera's exposure cannot be set from Albedit."
        self.auto = AutoExposure(**self._auto_args)
        self.black, self.frames, self.message = None, 0, ""
        self.level = "black"
        return ""

    def on_frame(self, f: LiveFrame) -> None:
        """A judged frame arrived (UI thread): take the next auto-exposure step from it."""
        if self.auto is None or f.level != self.level or f.asked != self.exposure:
            return  # not auto, or grabbed before the last change
        if f.level == "black":
            self.black = f.image
            self.level = "white"
            return
        self.frames += 1
        lit = f.lit if f.lit is not None else projector_lit(f.image, self.black)
        wanted = self.auto.step(f.image, f.saturated, exposure=f.exposure, target=lit, full_scale=f.full_scale)
        if wanted is None:
            if f.full_scale is not None and np.isposinf(f.full_scale):
                self._stop(f"This camera does not clip (it returns radiance): every exposure gives the same data; "
                           f"kept {1000 * f.exposure:.4g} ms.")
            else:
                frames = f"{self.frames} frame" + ("s" if self.frames != 1 else "")
                self._stop(f"Auto exposure settled at {1000 * f.exposure:.4g} ms after {frames} (the "
                           "brightest projector-lit pixels at 80 % of full scale; a lamp in view may clip: captures "
                           "complete it from shorter exposures).")
        elif self.frames >= self.max_frames:
            self._stop(f"Auto exposure gave up after {self.frames} frames (no clipping seen and the camera does not "
                       "say where it clips): set the exposure by hand.")
        else:
            self.exposure = float(wanted)

    def status(self, f: LiveFrame) -> tuple[str, bool]:
        """The report line(s) for a shown frame, and whether the frame is usable."""
        lines = [f.report]
        if self.running:
            lines.insert(0, f"auto exposure: frame {self.frames + 1}…")
        elif self.message:
            lines.insert(0, self.message)
        return "\n".join(lines), f.ok

    def _stop(self, message: str) -> None:
        self.auto = None
        self.message = message
        if self.level == "black" and message:
            self.level = "white"
