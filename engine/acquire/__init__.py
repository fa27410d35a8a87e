"""Capture plans: calibration runs, single-target acquisition (Sec. 3.3, 6), cascades (Sec. 4)
and adaptive capture (Sec. 5). Everything talks to a rig through :class:`Recorder` only."""

from engine.acquire.cascade import CAPTURE_PREFIX, CascadeResult, acquire_cascade, acquire_single
from engine.acquire.checker import CheckerMeasurement, measure_checker, projector_xy
from engine.acquire.emission import Emission, Emitter, Negative
from engine.acquire.predict import Adaptive, Policy, Predictor
from engine.acquire.recorder import Recorder
from engine.acquire.rig_calibration import calibrate_rig, calibration_budget
from engine.acquire.steps import Acquisition, CaptureSettings, reemit
from engine.acquire.target import PreparedTarget, prepare_target

__all__ = [
    "CAPTURE_PREFIX",
    "Acquisition",
    "Adaptive",
    "CascadeResult",
    "CheckerMeasurement",
    "Policy",
    "Predictor",
    "acquire_cascade",
    "CaptureSettings",
    "Emission",
    "Emitter",
    "Negative",
    "PreparedTarget",
    "Recorder",
    "acquire_single",
    "calibrate_rig",
    "calibration_budget",
    "measure_checker",
    "prepare_target",
    "projector_xy",
    "reemit",
]
