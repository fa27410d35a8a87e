"""Rig calibration maths: pure functions on captured arrays, no devices.

Pattern generators return lazy sequences of float32 ``(Hp, Wp, 3)`` projector images in
[0, 1]; fitting functions take captures as float ``(H, W, 3)`` linear radiance (Gray-code
decoding also takes uint8/uint16 and grey images).

- :mod:`~engine.calibrate.exposure`: :func:`black_frame`, :func:`exposure_report`, :class:`AutoExposure`,
  :func:`projector_lit`.
- :mod:`~engine.calibrate.response`: :func:`ramp_levels`, :func:`response_patterns`,
  :func:`fit_response` → :class:`ProjectorResponse` (``forward``, ``linearize``).
- :mod:`~engine.calibrate.graycode`: :func:`gray_code_patterns`, :func:`decode_gray_code`
  → :class:`Correspondence`.
- :mod:`~engine.calibrate.warp`: :func:`warp_to_projector`, :func:`warp_to_camera`,
  :func:`projector_to_camera_map`, :func:`projector_footprint`, :func:`spread_patterns` → :func:`projector_spread`.
- :mod:`~engine.calibrate.direct`: :func:`high_frequency_patterns`, :func:`direct_image`
  → :class:`DirectImage` (the paper's D, Sec. 3.3).
- :mod:`~engine.calibrate.crosstalk`: :func:`crosstalk_patterns`, :func:`fit_crosstalk`
  → :class:`Crosstalk` (``unmix``).
- :mod:`~engine.calibrate.calibration`: :class:`Calibration` (JSON + arrays, compatibility).
"""

from engine.calibrate.calibration import CALIBRATION_VERSION, Calibration
from engine.calibrate.crosstalk import Crosstalk, crosstalk_patterns, fit_crosstalk
from engine.calibrate.direct import DirectImage, direct_image, high_frequency_patterns
from engine.calibrate.exposure import AutoExposure, ExposureReport, black_frame, exposure_report, projector_lit
from engine.calibrate.graycode import (
    GRAY_CODES,
    Correspondence,
    PixelStatus,
    decode_gray_code,
    fill_correspondence,
    gray_code_bits,
    gray_code_patterns,
)
from engine.calibrate.response import (
    ProjectorResponse,
    RampChannels,
    fit_response,
    ramp_levels,
    response_patterns,
)
from engine.calibrate.warp import (
    ProjectorMap,
    estimate_hole_radius,
    projector_footprint,
    projector_spread,
    projector_to_camera_map,
    spread_patterns,
    warp_to_camera,
    warp_to_projector,
)

__all__ = [
    "AutoExposure",
    "CALIBRATION_VERSION",
    "Calibration",
    "Correspondence",
    "Crosstalk",
    "DirectImage",
    "ExposureReport",
    "GRAY_CODES",
    "PixelStatus",
    "ProjectorMap",
    "ProjectorResponse",
    "RampChannels",
    "black_frame",
    "crosstalk_patterns",
    "decode_gray_code",
    "fill_correspondence",
    "direct_image",
    "estimate_hole_radius",
    "exposure_report",
    "fit_crosstalk",
    "fit_response",
    "gray_code_bits",
    "gray_code_patterns",
    "high_frequency_patterns",
    "projector_footprint",
    "projector_spread",
    "projector_lit",
    "projector_to_camera_map",
    "ramp_levels",
    "response_patterns",
    "spread_patterns",
    "warp_to_camera",
    "warp_to_projector",
]
