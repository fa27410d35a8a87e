"""Ground truth for a reopened session: the open simulated rig's scene, lit as the photograph was. Qt-free.

The demo hands its document the rig's truth when it makes it. A session saved from a simulated
rig and opened again has lost it; when that rig is open again (and is the one the session was
calibrated with), :func:`scene_truth` gives it back, so the Ground Truth and Error views work
on any session a simulated rig made, not only the demo's. The truth is trusted only after the
scene, lit as the session recorded it (the projector's pattern, the ambient switch), reproduces
the document's photograph: a wrong truth would be a silently wrong error figure.
"""

from __future__ import annotations

import numpy as np

from engine.acquire.predict import relative_error
from engine.errors import InputError, SessionError
from engine.workflow import check_rig, load_calibration, photograph_name, saved_edit
from engine.workflow.calibration import ACQUISITION_GROUP, PHOTOGRAPH_PATTERN

__all__ = ["MATCH", "SceneTruth", "scene_truth"]

#: Largest relative difference between the scene's noise-free photograph and the document's for the
#: truth to be used (a realistic camera's noise stays well below it; another lighting does not).
MATCH = 0.1


class SceneTruth:
    """A simulated rig's truth under fixed lighting: what :attr:`app.model.document.Document.truth` expects.

    Parameters
    ----------
    truth : devices.virtual.truth.Truth
        The rig's ground truth (``rig.truth``).
    pattern : (Hp, Wp, 3) float or None
        The projector's input while the photograph was taken (None: black).
    ambient : bool
        The ambient light's switch then.
    """

    def __init__(self, truth, pattern: np.ndarray | None, ambient: bool):
        self._truth, self.pattern, self.ambient = truth, pattern, bool(ambient)

    def photograph(self) -> np.ndarray:
        """The scene's noise-free photograph under this lighting, ``(H, W, 3)`` float32."""
        return self._truth.photograph(ambient=self.ambient, pattern=self.pattern)

    def recolor(self, pairs) -> np.ndarray:
        """The photograph with each ``(mask, kappa)`` pair's albedo scaled (see ``Truth.recolor``)."""
        return self._truth.recolor(pairs, ambient=self.ambient, pattern=self.pattern)

    def emitters(self) -> np.ndarray:
        """``(H, W)`` bool: the pixels that see a lamp."""
        return self._truth.emitters()


def scene_truth(rig, session, photograph: np.ndarray) -> tuple[SceneTruth | None, str]:
    """The open ``rig``'s ground truth for a document of ``session`` with ``photograph``, if it has one.

    Parameters
    ----------
    rig : devices.base.Rig or None
        The open rig (only a simulated one has ``truth``).
    session : engine.session.Session or None
        The document's session.
    photograph : (H, W, 3) float32
        The document's photograph.

    Returns
    -------
    truth, why
        ``(SceneTruth, "")``, or ``(None, reason)`` in words for a user (the rig is not the session's,
        or its scene does not reproduce the photograph).
    """
    truth = getattr(rig, "truth", None)
    if truth is None or session is None:
        return None, "only a simulated rig's scene has a ground truth"
    try:
        check_rig(load_calibration(session), rig)
    except (InputError, SessionError):
        return None, f"the open rig, {rig.name}, is not the one this session was calibrated with"
    if tuple(truth.shape) != tuple(photograph.shape[:2]):
        return None, f"the open rig's camera is {truth.shape[1]}×{truth.shape[0]}, the photograph " \
                     f"{photograph.shape[1]}×{photograph.shape[0]}"
    try:
        meta = session.capture_record(photograph_name(session, saved_edit(session))).meta
    except SessionError:
        meta = {}
    ambient = bool(meta.get("metadata", {}).get("ambient", getattr(rig, "ambient", True)))
    pattern = None
    if meta.get("kind") == "photograph":  # the acquisition's photograph: under the pattern it stored, if any
        try:
            pattern = session.read_array(ACQUISITION_GROUP, PHOTOGRAPH_PATTERN)
        except SessionError:
            pattern = None
    candidate = SceneTruth(truth, pattern, ambient)
    keep = ~candidate.emitters()
    miss = relative_error(photograph, candidate.photograph(), keep if keep.any() else None)
    if not miss <= MATCH:
        return None, f"the open rig's scene differs from this photograph by {100 * miss:.0f} % (another lighting?)"
    return candidate, ""
