"""Running a rig's calibration: the captures behind :class:`engine.calibrate.Calibration`.

Order: black frame, white frame (exposure check), repeated black and white frames (the
camera's noise), Gray code (correspondences, and the mask of projector-lit pixels),
projector response ramp on those pixels, optionally crosstalk. Every capture goes through a
:class:`Recorder`, so an interrupted calibration resumes.
"""

from __future__ import annotations

import datetime as _dt

import numpy as np

from engine.acquire.recorder import Recorder
from engine.calibrate import (
    Calibration,
    crosstalk_patterns,
    decode_gray_code,
    exposure_report,
    fit_crosstalk,
    fit_response,
    gray_code_patterns,
    projector_lit,
    ramp_levels,
    response_patterns,
)
from engine.errors import InputError
from engine.noise import fit_camera_noise
from engine.rig import fingerprint_of

#: Frames of each lighting (projector black, projector white) for the camera-noise fit.
NOISE_FRAMES = 4


def calibration_budget(projector_resolution, *, levels: int = 17, crosstalk: bool = False) -> int:
    """Number of captures :func:`calibrate_rig` takes."""
    gray = len(gray_code_patterns(projector_resolution))
    xtalk = len(crosstalk_patterns(projector_resolution)) if crosstalk else 0
    return 2 + 2 * NOISE_FRAMES + gray + 3 * levels + xtalk


def calibrate_rig(
    recorder: Recorder,
    *,
    rig_name: str,
    levels: int = 17,
    crosstalk: bool = False,
) -> Calibration:
    """Calibrate a camera–projector rig.

    Parameters
    ----------
    recorder : Recorder
        Wraps the rig (and the session the captures go to).
    rig_name : str
        Recorded in the calibration; a calibration is refused for another rig.
    levels : int
        Levels of the projector response ramp, shown on one primary at a time (3 × levels
        captures): acquisition emits one primary at a time, and a grey ramp would measure in
        each camera channel a mix of the primaries' curves (measured on the realistic virtual
        rig, whose primaries have gammas 2.2, 2.25 and 2.15 and 4–6 % crosstalk: every
        re-emission's light came out 0.34 % too dark in green and 0.1 % too bright in red and
        blue, a bias no averaging removes).
    crosstalk : bool
        Also measure the 3×3 projector-primary → camera-channel matrix.

    Returns
    -------
    Calibration
        With ``metadata["exposure"]`` (the exposure report as text), coverage counts and
        ``metadata["noise"]``: the camera's noise (:class:`engine.noise.CameraNoise`) fitted
        to the temporal variance of :data:`NOISE_FRAMES` frames under projector black and
        white (unbracketed; clipped pixels left out).

    Raises
    ------
    InputError
        The camera sees no projector light, the ramp is not monotonic, nothing decodes —
        each with a message in plain words.
    Cancelled
        The recorder's ``should_stop`` fired; finished captures stay in the session.
    """
    rig = recorder.rig
    cam_h, cam_w = rig.camera.resolution  # (H, W) of both devices
    cam_res = (int(cam_h), int(cam_w))
    proj_h, proj_w = rig.projector.resolution
    proj_res = (int(proj_h), int(proj_w))
    lv = ramp_levels(levels)  # checked before the first capture
    recorder.planned = calibration_budget(proj_res, levels=levels, crosstalk=crosstalk)
    black = recorder.capture("cal-black", recorder.black(), meta={"kind": "calibration"})
    white = recorder.capture("cal-white", np.ones(proj_res + (3,), np.float32), meta={"kind": "calibration"})
    if float(np.percentile(white - black, 99)) <= 0.01 * max(float(np.percentile(white, 99.9)), 1e-30):
        raise InputError(
            "the camera saw no change between projector black and white: is the projector on, "
            "pointed at the scene, and the camera's exposure long enough?"
        )
    lit = projector_lit(white, black)  # judged where calibration measures: projector light, as the wizard judges
    report_ = exposure_report(white, saturated=recorder.last_saturated, black=black, target=lit,
                              label=None if lit is None else "projector-lit pixels")
    noise = _measure_noise(recorder, proj_res)
    gray = gray_code_patterns(proj_res)
    gray_caps = [recorder.capture(f"cal-xor-{i:03d}", p, meta={"kind": "calibration"}) for i, p in enumerate(gray)]
    corr = decode_gray_code(gray_caps, proj_res)
    if not corr.valid.any():
        raise InputError("no camera pixel decoded the Gray code: "
                         "check focus, exposure and that the projector lights the scene")
    ramp = [recorder.capture(f"cal-ramp-{i:03d}", p, meta={"kind": "calibration"})
            for i, p in enumerate(response_patterns(lv, proj_res, channels="separate"))]
    response = fit_response(np.stack(ramp), lv, channels="separate", mask=corr.valid)
    xtalk = None
    if crosstalk:
        prim = [recorder.capture(f"cal-primary-{i}", p, meta={"kind": "calibration"})
                for i, p in enumerate(crosstalk_patterns(proj_res))]
        xtalk = fit_crosstalk(np.stack(prim), black=black, mask=corr.valid)
    return Calibration(
        rig_name=rig_name,
        camera_resolution=cam_res,
        projector_resolution=proj_res,
        black_frame=black,
        response=response,
        correspondence=corr,
        crosstalk=xtalk,
        metadata={
            "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            "exposure": str(report_),
            "coverage": corr.summary(),
            "rig_fingerprint": fingerprint_of(rig),
            "exposure_s": float(getattr(rig.camera, "exposure", 0.0) or 0.0),
            "gain": float(getattr(rig.camera, "gain", 1.0) or 1.0),
            "noise": noise.to_dict(),
        },
    )


def _measure_noise(recorder: Recorder, projector_resolution):
    """Repeated frames under projector black and white, single and unbracketed: the camera noise."""
    brackets, frames = recorder.brackets, recorder.frames
    recorder.brackets, recorder.frames = 0, 1  # every pixel read at this exposure, one frame each
    try:
        stacks, clipped = [], None
        for label, level in (("black", 0.0), ("white", 1.0)):
            pattern = np.full(tuple(projector_resolution) + (3,), level, np.float32)
            shots = []
            for i in range(NOISE_FRAMES):
                shots.append(recorder.capture(f"cal-noise-{label}-{i}", pattern, meta={"kind": "calibration"}))
                sat = np.asarray(recorder.last_saturated, bool)
                clipped = sat if clipped is None else clipped | sat
            stacks.append(np.stack(shots))
    finally:
        recorder.brackets, recorder.frames = brackets, frames
    exposure = float(getattr(recorder.rig.camera, "exposure", 1.0) or 1.0)
    return fit_camera_noise(stacks, exposure, saturated=clipped)
