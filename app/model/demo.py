"""The virtual-rig demo, Qt-free: open ``virtual:cornell``, calibrate, acquire, make a document.

It reproduces the paper's Fig. 6: the right wall of the Cornell-like box is the target,
acquired at 4th order on the simulated rig through :mod:`engine.workflow` (the same code the
``albedit capture`` command runs), and recolored from green to blue with
κ = (2.0, 0.125, 8.0). The scene's other targets are painted but not acquired (and left out
of the next acquisition until the user includes them).

The desktop app and ``albedit demo`` share one default rig, :data:`DEMO_OPTIONS`: the ideal
camera and projector (no noise, linear), where every number can be checked against the
rig's exact ground truth; the realistic rig is one option away.

The demo's session lives in a cache folder (the app passes the user cache directory), one
folder per rig set-up (:func:`demo_key`): a second start with the same rig reuses its
calibration and captures and opens in about a second; the oldest other demo sessions are
deleted so at most :data:`KEEP` remain. Nothing is left in the temporary directory.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.model.document import Document
from app.model.files import unlit_pixels
from engine.errors import InputError, SessionError
from engine.progress import checkpoint, report

DEMO_RIG = "virtual:cornell"
#: The target acquired in the demo and its κ (paper, Fig. 6: green (0.1, 0.8, 0.1) → blue (0.2, 0.1, 0.8)).
DEMO_TARGET = "right_wall"
DEMO_KAPPA = (2.0, 0.125, 8.0)
#: The albedo the demo gives its target: Fig. 6's blue (:func:`demo_kappa`).
DEMO_ALBEDO = (0.2, 0.1, 0.8)
DEMO_ORDER = 4
#: The one default rig of the app's and the CLI's demo: ideal, co-axial, seeded.
DEMO_OPTIONS: dict[str, Any] = {"ideal": True, "projector": "coaxial", "seed": 0}
#: Demo sessions kept in the cache folder (the one in use and the most recent others).
KEEP = 2
#: Square resolutions the app's demo picks from (:func:`demo_resolution`): at most 512², because
#: on the ideal co-axial Cornell box the Gray code does not decode the right wall next to the back
#: wall's corner beyond what acquisition estimates from neighbours (3 px), and those pixels keep
#: their green: 640²: 7443 of 66804 wall pixels, 768²: 751, 896²: 1216, 1024²: 961 — a visible
#: streak; 256² and 512²: none. A 512² demo is drawn smoothed (165 % in a 1500×920 window).
SIDES = (256, 512)


@dataclass
class Demo:
    """What :func:`open_demo` made."""

    document: Document
    rig: Any
    session: Any  # engine.session.Session, None without acquisition
    options: dict  # the options the rig was opened with (JSON-able: how to reopen it)


def default_folder() -> Path:
    """Where demo sessions go (the app's and ``albedit demo``'s): ``$XDG_CACHE_HOME/albedit/demo``, beside the
    virtual and path-traced rigs' caches."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "albedit" / "demo"


def demo_resolution(canvas: tuple[int, int]) -> tuple[int, int]:
    """The square demo resolution for a canvas of ``canvas`` (h, w) device pixels.

    The smallest of :data:`SIDES` at least as large as the canvas's shorter side (shown at 100 %
    or less), else the largest of them.

    Examples
    --------
    >>> demo_resolution((200, 300)), demo_resolution((480, 900)), demo_resolution((900, 1400))
    ((256, 256), (512, 512), (512, 512))
    """
    side = min(int(canvas[0]), int(canvas[1]))
    s = next((s for s in SIDES if s >= side), SIDES[-1])
    return (s, s)


def demo_kappa(rig, mask: np.ndarray) -> np.ndarray:
    """κ that gives the demo's target Fig. 6's blue (:data:`DEMO_ALBEDO`), from the rig's true albedo.

    On the Cornell box's green right wall this is Fig. 6's κ, :data:`DEMO_KAPPA`. Fig. 6's κ on
    another wall can ask for an albedo no surface has (the checker scene's blue wall, albedo 0.6
    in blue, would get 4.8: more light than it receives, whose interaction series an order-K
    decomposition cannot follow), so the demo aims at the colour, not the factor.

    Parameters
    ----------
    rig
        A rig whose ``truth`` may offer ``albedo()``, (H, W, 3) per pixel.
    mask : (H, W) bool
        The target.

    Returns
    -------
    (3,) float64
        The target's median true albedo divided into :data:`DEMO_ALBEDO`, to three decimals;
        :data:`DEMO_KAPPA` when the rig does not know its albedo (the path-traced rigs).
    """
    albedo_of = getattr(rig.truth, "albedo", None)
    if albedo_of is None:
        return np.array(DEMO_KAPPA)
    # the median: a supersampled rig's edge pixels mix the neighbour's albedo in (their mean made the realistic
    # 128² demo's κ (1.865, 0.125, 7.503) for the wall's (2, 0.125, 8))
    albedo = np.median(np.asarray(albedo_of(), np.float64)[np.asarray(mask, bool)], axis=0)
    if not np.all(albedo > 0):
        return np.array(DEMO_KAPPA)
    return np.round(np.array(DEMO_ALBEDO) / albedo, 3)


def demo_key(rig_name: str, rig, options: dict) -> str:
    """Names one demo set-up: scene content, camera model, resolution, pose, seed, the demo's plan."""
    from devices.virtual.setup import MODEL_DIGEST
    from engine.workflow import rig_metadata

    blob = json.dumps({"rig": rig_name, "scene": getattr(getattr(rig, "scene", None), "digest", ""),
                       "model": MODEL_DIGEST, "options": {k: options[k] for k in sorted(options)},
                       "camera": list(rig.camera.resolution), "projector": list(rig.projector.resolution),
                       "target": DEMO_TARGET, "order": DEMO_ORDER,
                       # what its session records about the rig (a session made before it recorded the projector's
                       # bit depth is replayed as 8-bit's: built again)
                       "session": rig_metadata(rig)}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _stage(progress, name: str):
    """A progress callback that prefixes ``name`` to the engine's messages."""
    if progress is None:
        return None
    return lambda step, total, message: progress(step, total, f"{name}: {message}")


def _prune(folder: Path, keep: Path) -> None:
    """Delete the oldest demo sessions in ``folder`` so that at most :data:`KEEP` remain (``keep`` stays)."""
    others = sorted((p for p in folder.glob("demo-*") if p.is_dir() and p != keep),
                    key=lambda p: p.stat().st_mtime, reverse=True)
    for old in others[KEEP - 1:]:
        shutil.rmtree(old, ignore_errors=True)


def _session(folder: Path, rig_name: str, rig, options: dict):
    """The demo's session for this rig: reused (resumed, when a start was killed) or new."""
    from engine.session import Session
    from engine.workflow import rig_metadata

    path = folder / f"demo-{rig_name.partition(':')[2]}-{demo_key(rig_name, rig, options)}"
    if (path / "manifest.json").exists():
        try:
            session = Session.open(path)
            session.recover_orphans()
            os.utime(path)  # the most recently used
            return session
        except SessionError:  # damaged (e.g. killed while creating it): start again
            shutil.rmtree(path, ignore_errors=True)
    elif path.exists():
        shutil.rmtree(path, ignore_errors=True)
    return Session.create(path, rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                          projector_resolution=rig.projector.resolution, metadata=rig_metadata(rig, demo=True))


def open_demo(rig_name: str = DEMO_RIG, *, acquire: bool = True, folder=None, progress=None, should_stop=None,
              **rig_options) -> Demo:
    """Open a virtual rig and make the demo document.

    Parameters
    ----------
    rig_name : str
        A virtual rig with scene targets and ground truth.
    acquire : bool
        Calibrate the rig and acquire :data:`DEMO_TARGET` (seconds the first time); False only
        takes the photograph and paints the scene targets.
    folder : str or Path, optional
        The cache folder of demo sessions (default :func:`default_folder`).
    progress, should_stop
        :mod:`engine.progress` conventions; cancelling stops between captures (a later start
        resumes from what was captured).
    **rig_options
        Passed to :func:`devices.open_rig` over :data:`DEMO_OPTIONS` (e.g. ``resolution``).

    Returns
    -------
    Demo
        The document (clean, scene targets painted; with ``acquire`` the right wall acquired
        and recolored as in Fig. 6, the pixels the projector does not light marked
        unreachable), the open rig (its ``truth`` feeds the ground-truth views: close it
        with the window), the session, the rig options.
    """
    from devices import open_rig  # the app sits above devices; imported late to keep start-up light
    from engine.workflow import (
        decomposition_key,
        load_calibration,
        load_decomposition,
        photograph_name,
        run_calibration,
        run_capture,
    )

    options = dict(DEMO_OPTIONS, **rig_options)
    saved = {k: v for k, v in options.items() if k not in ("progress", "cache_dir")}
    saved = {k: list(v) if isinstance(v, tuple) else v for k, v in saved.items()}
    report(progress, 0, 1, f"opening {rig_name} (the first start builds its light transport: a few seconds)")
    rig = open_rig(rig_name, progress=_stage(progress, "building the scene"), **options)
    try:
        checkpoint(should_stop, "opening the demo")
        targets = {name: np.asarray(mask, bool) for name, mask in rig.targets.items()}
        if DEMO_TARGET not in targets:
            raise InputError(f"{rig_name} has no target {DEMO_TARGET!r}; it has {sorted(targets)}")
        if not acquire:
            doc = Document(np.asarray(rig.camera.capture().image, np.float32), source=rig_name, truth=rig.truth)
            for name, mask in targets.items():
                doc.add_target(name, mask)
            _finish(doc)
            return Demo(doc, rig, None, saved)
        root = Path(folder) if folder is not None else default_folder()
        root.mkdir(parents=True, exist_ok=True)
        session = _session(root, rig_name, rig, saved)
        _prune(root, Path(session.path))
        decomposition = None
        if session.state.get("status") == "captured":  # a complete earlier start: read, don't re-run
            report(progress, 0, 1, "reading the demo's session")
            try:
                calibration = load_calibration(session)
                photo = session.read_capture(photograph_name(session))
                key = decomposition_key(session)
                decomposition = load_decomposition(session, key)
            except (SessionError, InputError):  # made by an older Albedit whose acquisition differs
                shutil.rmtree(session.path, ignore_errors=True)  # the demo's own cache: built again
                session = _session(root, rig_name, rig, saved)
        if decomposition is None:
            calibration = run_calibration(rig, session, progress=_stage(progress, "calibrating"),
                                          should_stop=should_stop)
            result = run_capture(rig, session, [(DEMO_TARGET, targets[DEMO_TARGET])], DEMO_ORDER,
                                 progress=_stage(progress, f"acquiring {DEMO_TARGET!r}"), should_stop=should_stop)
            photo, decomposition, key = result.acquisition.observations[0], result.decomposition, result.key
        photo = np.ascontiguousarray(photo, np.float32)
        doc = Document(photo, unreachable=unlit_pixels(calibration), source=rig_name, truth=rig.truth)
        for other, mask in targets.items():  # the acquired target last: the end of its cascade
            if other != DEMO_TARGET:
                t = doc.add_target(other, mask)
                doc.set_included(t.uid, False)  # painted for reference, not measured
        t = doc.add_target(DEMO_TARGET, targets[DEMO_TARGET])
        doc.set_acquisition([t.uid], decomposition, key=key)
        doc.set_kappa(t.uid, demo_kappa(rig, targets[DEMO_TARGET]))
        _finish(doc)
        report(progress, 1, 1, "ready")
        return Demo(doc, rig, session, saved)
    except BaseException:
        rig.close()
        raise


#: The capture the demo refines its target's edge from (a photograph: projector at black).
EDGE_PHOTOGRAPH = "edge-photograph"


def refined_target(rig, session, mask: np.ndarray, *, frames: int = 1, progress=None,
                   pattern: np.ndarray | None = None) -> np.ndarray:
    """The demo's target as an artist paints it: the scene's mask, its edge refined from a photograph.

    Takes (or reuses) the session's :data:`EDGE_PHOTOGRAPH`, under projector black or under
    ``pattern`` (the flood that lights a scene with no other light), and returns
    :func:`engine.edge.refine_mask` of ``mask`` on it: float coverage, 1 inside, the fraction
    of the target on edge pixels (pixels mixing the target and its neighbour, as every real
    camera and the supersampled realistic rig have). Acquisition re-emits only its solid pixels
    and recolors edge pixels from both sides (:mod:`engine.edge`).
    """
    from engine.acquire import Recorder
    from engine.edge import refine_mask

    recorder = Recorder(rig, session, progress=progress, frames=frames)
    photo = recorder.capture(EDGE_PHOTOGRAPH, recorder.black() if pattern is None else pattern, meta={"kind": "edge"})
    return refine_mask(np.asarray(mask, bool), photo)


def _finish(doc: Document) -> None:
    if doc.targets:
        doc.set_current(doc.targets[-1].uid)
    doc.history.clear()
    doc.mark_saved()
