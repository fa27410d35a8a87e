"""The headless workflow shared by the CLI and the app: calibrate, check, capture, decompose, save the edit.

Each step reads and writes a :class:`engine.session.Session`, so it can be interrupted and
resumed, and re-run offline from the session alone. Nothing here imports Qt or ``devices``:
callers open the rig. The app's widgets and the ``albedit`` commands call these functions
rather than repeating their checks:

- :mod:`~engine.workflow.calibration`: :func:`run_calibration` and
  :func:`calibration_problems` (what limits a calibration and how to fix it);
  :func:`load_compatible_calibration` and :func:`adopt_calibration` reuse another session's;
- :mod:`~engine.workflow.capture`: :func:`preflight` checks everything a capture needs before
  the first capture, and :func:`run_capture` runs it, returning the decomposition and its
  cache key;
- :mod:`~engine.workflow.decomposition`: :func:`load_decomposition` reads a decomposition from
  the session's cache, or recomputes it from the session's own captures when the cache is
  gone or unusable (no rig needed); :mod:`~engine.workflow.trusted`: :func:`load_trusted`
  does the same for the noise-aware recolor's data (:mod:`engine.trust`);
- :mod:`~engine.workflow.colour`: :func:`run_checker` measures a colour checker into the
  session, :func:`target_colour` tells a target's colour and, with the checker, its absolute
  albedo (each target's D is kept by :func:`run_capture`);
- :mod:`~engine.workflow.edit`: the saved edit (:mod:`engine.session.edit`), read by
  :func:`saved_edit` (including what older versions wrote) and written by :func:`save_edit`.
"""

from engine.workflow.calibration import (
    adopt_calibration,
    calibration_problems,
    check_rig,
    load_calibration,
    load_compatible_calibration,
    open_session_for_rig,
    rig_metadata,
    run_calibration,
    save_calibration,
)
from engine.workflow.capture import (
    MAX_FRAMES,
    CaptureResult,
    Preflight,
    Unreachable,
    capture_plan,
    check_frames,
    check_targets,
    estimated_report,
    preflight,
    run_capture,
)
from engine.workflow.colour import (
    RELATIVE,
    run_checker,
    saved_checker,
    store_directs,
    target_albedo,
    target_colour,
    target_direct,
)
from engine.workflow.decomposition import (
    cached_decomposition,
    decomposition_key,
    denoised_key,
    load_decomposition,
    noise_reduced,
    photograph_name,
)
from engine.workflow.edit import edit_from_plan, interrupted_edit, save_edit, saved_edit
from engine.workflow.trusted import NoNoiseModel, load_trusted, trusted_key

__all__ = [
    "MAX_FRAMES", "RELATIVE", "CaptureResult", "NoNoiseModel", "Preflight", "Unreachable", "adopt_calibration",
    "cached_decomposition",
    "calibration_problems", "capture_plan", "check_frames", "check_rig", "check_targets", "decomposition_key",
    "denoised_key", "edit_from_plan", "estimated_report", "interrupted_edit", "load_calibration",
    "load_compatible_calibration",
    "load_decomposition", "load_trusted", "noise_reduced", "open_session_for_rig", "photograph_name", "preflight",
    "rig_metadata", "run_calibration", "run_capture", "run_checker", "save_calibration", "save_edit", "saved_checker",
    "saved_edit",
    "store_directs", "target_albedo", "target_colour", "target_direct", "trusted_key",
]
