"""The session's decomposition: cached under a key of everything it depends on, else recomputed.

The cache is disposable: an entry that is missing, unreadable, of the wrong shape or holding
non-finite values counts as missing, and the decomposition is recomputed from the session's
own captures (every capture of a finished plan is in the session, so no rig is needed).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
from dataclasses import dataclass

from engine.acquire import Adaptive, CaptureSettings, CascadeResult, Recorder, acquire_cascade
from engine.decompose import Decomposition
from engine.denoise import denoise_components
from engine.errors import DeviceError, InputError, SessionError
from engine.progress import Progress, ShouldStop
from engine.rig import Camera, Frame, Projector
from engine.session import Session
from engine.session.edit import Edit, mask_name
from engine.workflow.calibration import ACQUISITION_GROUP, PHOTOGRAPH_PATTERN, load_calibration

__all__ = [
    "DECOMPOSITION_VERSION", "cached_decomposition", "decomposition_key", "denoised_key", "load_decomposition",
    "noise_reduced", "photograph_name", "reacquired",
]

#: Bump when the decomposition's maths or its cache layout change: cached results of older code are recomputed.
DECOMPOSITION_VERSION = 8  # 3: a soft mask's blended edge pixels are kept (noise reduction leaves them out);
# 4: a soft mask is noise-reduced before its edge blend; 5: and its edge pixels' neighbour shares along the edge;
# 6: edge pixels against a void (or the frame's border) are wholly target; 7: edge pixels beside a textured target
# (or where the strip's directions disagree) take the radiance split, unless noise-reduced before the blend;
# 8: a decomposition keeps its observations summed over the target (Decomposition.observed)


def decomposition_key(session: Session) -> str:
    """Cache key of the session's decomposition: its plan, its captures' checksums, its calibration, the code.

    Any change of these gives another key, so a cached result computed from other captures (a
    cache copied from another session) or by other code is never returned for this session.
    """
    try:
        version = importlib.metadata.version("albedit")
    except importlib.metadata.PackageNotFoundError:  # a source tree that was never installed
        version = "source"
    blob = json.dumps({
        "plan": session.state.get("plan"),
        "captures": sorted((c.name, c.sha256) for c in session.captures),
        "calibration": session.read_calibration(groups=())[0],
        "code": [version, DECOMPOSITION_VERSION],
    }, sort_keys=True).encode()
    return "decomposition-" + hashlib.sha256(blob).hexdigest()[:16]


def denoised_key(key: str, radius: int) -> str:
    """Cache key of decomposition ``key`` noise-reduced with ``radius`` (:mod:`engine.denoise`)."""
    return f"{key}-denoise{radius}"


def load_decomposition(session: Session, key: str | None = None, *, rig=None, denoise: int = 0,
                       photograph: str | None = None, notes: list[str] | None = None) -> Decomposition:
    """The session's decomposition: from the cache, else recomputed from the session's captures.

    Parameters
    ----------
    session : Session
    key : str, optional
        Cache key (a saved edit's); default :func:`decomposition_key` of the session's plan.
    rig : RigLike, optional
        Where to take captures the session lacks (normally none: every capture of a finished
        plan is in the session, and a recompute needs no rig).
    denoise : int
        Noise-reduction radius (0: the measured decomposition); a noise-reduced copy is cached
        under its own key.
    photograph : str, optional
        The capture guiding the noise reduction (default :func:`photograph_name`).
    notes : list of str, optional
        Receives a line when a cache entry was unusable and the result was recomputed.

    Raises
    ------
    SessionError
        No acquisition in the session, or a capture needed for the recompute is missing.
    """
    key = key or decomposition_key(session)
    d = cached_decomposition(session, key, notes)
    if d is None:
        d = _recompute(session, rig)
        _cache_best_effort(session, key, d)
    if denoise <= 0:
        return d
    return cached_decomposition(session, denoised_key(key, denoise), notes) or noise_reduced(
        session, key, d, denoise, photograph=photograph)


def noise_reduced(session: Session, key: str, decomposition: Decomposition, radius: int, *,
                  photograph: str | None = None, progress: Progress | None = None,
                  should_stop: ShouldStop | None = None) -> Decomposition:
    """``decomposition`` (cached under ``key``) noise-reduced with ``radius``, and cached under its own key.

    Guided by the session's photograph (:func:`photograph_name`, or the capture ``photograph``);
    see :func:`engine.denoise.denoise_components`. A soft mask's decomposition (one with
    blended edge pixels) is instead recomputed from the session's captures with the filter
    before the edge blend (:meth:`engine.acquire.PreparedTarget.decompose` ``denoise=``, guided
    by the acquisition's photograph), so that the blend extrapolates each edge pixel's target
    part from filtered target pixels and splits a filtered edge pixel: on the path-traced
    Cornell box (64², κ = (2, 0.125, 8), radius 4) its edge pixels' error is 7.9 % this way,
    11.9 % filtering the blended decomposition (which leaves the blended pixels out). When the
    session cannot give the acquisition back, the blended decomposition is filtered.
    A session that cannot be written (read-only, locked by another writer) still gets the
    result, uncached. ``progress`` and ``should_stop`` are passed to the filter (and
    ``should_stop`` to the recompute), as :func:`engine.denoise.denoise_components` takes them.
    """
    filtered = None
    if decomposition.blended is not None and decomposition.blended.any():
        try:
            filtered = _recompute(session, denoise=radius, should_stop=should_stop)
        except (SessionError, DeviceError, InputError):
            filtered = None  # the captures are not all there: filter what we have
    if filtered is None:
        photo = session.read_capture(photograph or photograph_name(session))
        filtered = denoise_components(decomposition, photo, radius=radius, progress=progress,
                                      should_stop=should_stop)
    _cache_best_effort(session, denoised_key(key, radius), filtered)
    return filtered


def cached_decomposition(session: Session, key: str, notes: list[str] | None = None) -> Decomposition | None:
    """The decomposition cached under ``key``, or None if there is none or it is unusable.

    An entry that is not a decomposition, of another resolution, or holding non-finite
    values is deleted and reported in ``notes``.
    """
    arrays = session.cache_get(key)
    if arrays is None:
        return None
    h, w = session.camera_resolution
    try:
        d = Decomposition.from_arrays(arrays)
        if d.shape[:2] != (h, w):
            raise InputError(f"it is {d.shape[1]}×{d.shape[0]}, the session {w}×{h}")
    except InputError as exc:
        discard_unusable(session, key, f"the cached decomposition {key!r} was unusable ({exc}); recomputed it "
                         "from the captures", notes)
        return None
    return d


def discard_unusable(session: Session, key: str, note: str, notes: list[str] | None) -> None:
    """Delete the unusable cache entry ``key`` (best effort: a read-only session keeps it) and
    append ``note`` to ``notes``."""
    if notes is not None:
        notes.append(note)
    try:
        session.cache_discard(key)
    except (OSError, SessionError):
        pass


def _cache_best_effort(session: Session, key: str, d: Decomposition) -> None:
    try:
        session.cache_put(key, d.to_arrays())
    except (OSError, SessionError):
        pass  # a read-only session: the result is returned all the same


class _OfflineCamera:
    """A camera that has no frames: a recompute finds every capture in the session or fails."""

    resolution: tuple[int, int]
    exposure: float
    gain: float

    def __init__(self, session: Session):
        self.resolution = session.camera_resolution
        self.exposure, self.gain = 1.0, 1.0
        self._path = session.path

    def capture(self) -> Frame:
        raise DeviceError(f"session {self._path} lacks a capture its plan needs; recapture with the rig "
                          "(`albedit capture` on the same session resumes)")


class _OfflineProjector:
    resolution: tuple[int, int]
    bit_depth: int

    def __init__(self, session: Session):
        self.resolution = session.projector_resolution
        self.bit_depth = int(session.metadata.get("projector_bit_depth", 8))

    def show(self, image) -> None:
        return None


@dataclass
class _OfflineRig:
    """The rig a recompute runs on: the session's own captures, served by name."""

    name: str
    identity: str
    camera: Camera
    projector: Projector

    @classmethod
    def of(cls, session: Session) -> _OfflineRig:
        return cls(session.rig_name, session.rig_name, _OfflineCamera(session), _OfflineProjector(session))


def _recompute(session: Session, rig=None, *, denoise: int = 0, should_stop: ShouldStop | None = None) -> Decomposition:
    result = reacquired(session, rig, should_stop=should_stop)
    return result.targets[-1][1].decompose(result.acquisition.observations, covariance=result.acquisition.covariance,
                                           denoise=denoise)


def reacquired(session: Session, rig=None, *, progress: Progress | None = None, should_stop=None) -> CascadeResult:
    """The session's acquisition rebuilt from its own captures (no rig needed when they are all there);
    ``progress`` counts the captures read (:mod:`engine.progress`).

    Raises
    ------
    SessionError
        No acquisition in the session, or a capture its plan needs is missing.
    """
    plan = session.state.get("plan")
    if plan is None:
        raise SessionError(f"session {session.path} has no acquisition: run `albedit capture` first")
    masks = set(session.masks)
    targets = []
    for name, digest in zip(plan["targets"], plan["masks"], strict=True):
        stored = mask_name(name, digest)
        targets.append((name, session.read_mask(stored if stored in masks else name)))  # older sessions: by name
    settings = CaptureSettings.from_dict(plan["settings"])
    adaptive = None if plan["adaptive"] is None else Adaptive(**plan["adaptive"])
    # a photograph under a projector pattern (capture --flood) is found by that pattern; sessions captured before
    # it was stored cannot be replayed (SessionError: the captures say which pattern they were taken with)
    pattern = session.read_array(ACQUISITION_GROUP, PHOTOGRAPH_PATTERN) if plan["photograph_pattern"] else None
    recorder = Recorder(_OfflineRig.of(session) if rig is None else rig, session, progress=progress,
                        should_stop=should_stop)
    return acquire_cascade(recorder, load_calibration(session), targets, plan["order"],
                           fixed_kappa=plan["fixed_kappa"], settings=settings, adaptive=adaptive,
                           photograph_pattern=pattern)


def photograph_name(session: Session, edit: Edit | None = None) -> str:
    """The capture the edit recolors.

    The edit's ``photograph``, else ``state["photograph"]``, else a capture named
    ``"photograph"``, else the last capture whose metadata says ``kind: "photograph"`` (what
    :func:`run_capture` takes), else the first capture.

    Raises
    ------
    SessionError
        The session has no capture.
    """
    records = session.captures
    names = [c.name for c in records]
    if not names:
        raise SessionError(f"session {session.path} has no capture: there is no photograph to edit")
    for candidate in (None if edit is None else edit.photograph, session.state.get("photograph"), "photograph"):
        if isinstance(candidate, str) and candidate in names:
            return candidate
    kinds = [c.name for c in records if c.meta.get("kind") == "photograph"]
    return kinds[-1] if kinds else names[0]
