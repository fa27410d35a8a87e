"""Calibrating a rig into a session, reusing another session's calibration, and advice on the result."""

from __future__ import annotations

from pathlib import Path

from engine.acquire import Recorder, calibrate_rig
from engine.calibrate import Calibration
from engine.errors import InputError, SessionError
from engine.progress import Progress, ShouldStop
from engine.rig import fingerprint_differences, fingerprint_of
from engine.session import Session
from engine.session.colour import COLOUR_GROUP

__all__ = [
    "adopt_calibration", "calibration_problems", "check_rig", "load_calibration", "load_compatible_calibration",
    "open_session_for_rig", "rig_metadata", "run_calibration", "save_calibration",
]

_CALIBRATION_GROUP = "rig"
#: The session's arrays an acquisition needs to be replayed (its photograph's projector pattern): kept by a
#: recalibration, as the colour group is.
ACQUISITION_GROUP = "acquisition"
#: The projector pattern the photograph was taken under (``capture --flood``), in :data:`ACQUISITION_GROUP`.
PHOTOGRAPH_PATTERN = "photograph_pattern"


def rig_metadata(rig, **extra) -> dict:
    """The facts about ``rig`` a session must record for its captures to be replayed offline.

    The projector's input bit depth decides how much rounding noise a re-emitted pattern
    carries (:func:`engine.noise.quantization_variance`); a session without it is replayed as
    an 8-bit projector's, so the noise-aware recolor of an ideal (float) projector's captures
    would smooth away detail that is not noise.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> rig_metadata(SimpleNamespace(projector=SimpleNamespace(bit_depth=24)), demo=True)
    {'projector_bit_depth': 24, 'demo': True}
    """
    return {"projector_bit_depth": int(getattr(rig.projector, "bit_depth", 8)), **extra}


def open_session_for_rig(path, rig, **metadata) -> Session:
    """Open the session at ``path`` (adopting orphan captures) or create one for ``rig``.

    ``metadata``: extra facts a new session records beside :func:`rig_metadata`'s (e.g. ``demo=True``).

    Raises
    ------
    SessionError
        ``path`` is a session of another rig or resolution, or cannot be created.
    """
    path = Path(path)
    if (path / "manifest.json").exists():
        session = Session.open(path)
        session.recover_orphans()
        theirs = (session.rig_name, tuple(session.camera_resolution), tuple(session.projector_resolution))
        ours = (rig.identity, tuple(rig.camera.resolution), tuple(rig.projector.resolution))
        if theirs != ours:
            raise SessionError(
                f"session {path} belongs to rig {theirs[0]!r} (camera {theirs[1]}, projector {theirs[2]}), "
                f"not to {ours[0]!r} (camera {ours[1]}, projector {ours[2]}); choose a new session folder"
            )
        recorded = session.fingerprint
        differences = [] if recorded is None else fingerprint_differences(recorded, fingerprint_of(rig))
        if differences:
            raise SessionError(f"session {path} was recorded with another set-up of rig {rig.identity!r}: "
                               f"{'; '.join(differences)}; choose a new session folder")
        return session
    return Session.create(
        path,
        rig_name=rig.identity,
        camera_resolution=tuple(rig.camera.resolution),
        projector_resolution=tuple(rig.projector.resolution),
        metadata=rig_metadata(rig, **metadata),
        fingerprint=fingerprint_of(rig),
    )


def save_calibration(session: Session, calibration: Calibration) -> None:
    """Store a calibration in a session (JSON + lossless arrays), keeping the session's colour facts."""
    meta, arrays = calibration.to_dict()
    session.write_calibration(meta, {_CALIBRATION_GROUP: arrays}, keep=(COLOUR_GROUP, ACQUISITION_GROUP))


def load_calibration(session: Session) -> Calibration:
    """Read the session's calibration.

    Raises
    ------
    SessionError
        The session has none, or it is malformed (the message says what and to recalibrate).
    """
    meta, arrays = session.read_calibration(groups=(_CALIBRATION_GROUP,))
    if not meta:
        raise SessionError(f"session {session.path} has no calibration: calibrate the rig into it first "
                           "(`albedit calibrate`, or Calibrate the rig… in the app)")
    try:
        return Calibration.from_dict(meta, arrays.get(_CALIBRATION_GROUP, {}))
    except (InputError, KeyError, TypeError, ValueError) as exc:
        raise SessionError(f"session {session.path}: its calibration is malformed ({exc}); recalibrate") from None


def load_compatible_calibration(source, rig) -> Calibration:
    """The calibration of the session at ``source``, if it fits ``rig``.

    Raises
    ------
    SessionError
        ``source`` is not a calibrated session.
    InputError
        The calibration was made for another rig, resolution or set-up (the message says what differs).
    """
    calibration = load_calibration(Session.open(source))
    check_rig(calibration, rig)
    return calibration


def check_rig(calibration: Calibration, rig) -> None:
    """InputError unless ``calibration`` was made with ``rig`` as it is set up now (name, resolutions, fingerprint)."""
    calibration.check_compatible(rig.identity, tuple(rig.camera.resolution), tuple(rig.projector.resolution),
                                 fingerprint_of(rig))


def adopt_calibration(session: Session, calibration: Calibration) -> None:
    """Use ``calibration`` (e.g. from :func:`load_compatible_calibration`) in ``session``.

    Raises
    ------
    SessionError
        The session already has a different calibration.
    """
    mine = session.read_calibration(groups=())[0]
    if mine and mine != calibration.to_dict()[0]:
        raise SessionError(f"session {session.path} already has a different calibration; use a new session folder")
    if not mine:
        save_calibration(session, calibration)


def run_calibration(
    rig,
    session: Session,
    *,
    levels: int = 17,
    crosstalk: bool = False,
    progress: Progress | None = None,
    should_stop: ShouldStop | None = None,
) -> Calibration:
    """Calibrate ``rig`` into ``session`` (resumable); see :func:`engine.acquire.calibrate_rig`.

    The session's lock is held throughout: another process cannot write the session meanwhile.
    """
    with session.writing("calibrating the rig"):
        return _calibrate(rig, session, levels=levels, crosstalk=crosstalk, progress=progress, should_stop=should_stop)


def _calibrate(rig, session: Session, *, levels, crosstalk, progress, should_stop) -> Calibration:
    recorder = Recorder(rig, session, progress=progress, should_stop=should_stop)
    calibration = calibrate_rig(recorder, rig_name=session.rig_name, levels=levels, crosstalk=crosstalk)
    save_calibration(session, calibration)
    return calibration


def calibration_problems(calibration: Calibration) -> list[tuple[str, str]]:
    """What limits a calibration, and how to fix it: ``[(what, fix), ...]`` (empty when all is well).

    Coverage: camera pixels the Gray code did not decode (unlit, low contrast, out of range),
    when more than 2 % of the frame; exposure: the white frame's report when it is not ok.
    """
    out = []
    counts = calibration.correspondence.counts()
    total = max(sum(counts.values()), 1)
    if counts["decoded"] < 0.98 * total:
        fixes = ["targets can only be edited where the projector reaches: keep them on the green "
                 "pixels of the coverage map"]
        if counts["unlit"]:
            fixes.append("unlit pixels are in the projector's shadow or see no surface (the void, a far "
                         "background): targets there cannot be edited; for shadows, place the projector closer to "
                         "the camera's viewpoint")
        if counts["low_contrast"]:
            fixes.append("low contrast: focus the projector, lengthen the exposure, darken the room")
        if counts["out_of_range"]:
            fixes.append("out of range codes come from noise or strong indirect light: darken the room")
        out.append((calibration.correspondence.summary(), "; ".join(fixes) + "."))
    exposure = str(calibration.metadata.get("exposure", ""))
    if exposure and not exposure.startswith("ok"):
        out.append((f"Exposure: {exposure}", "Adjust the exposure (the calibration wizard's exposure page, or the "
                                              "camera's settings) and calibrate into a new session folder."))
    return out
