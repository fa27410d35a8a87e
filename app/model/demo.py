"""The virtual-rig demo, Qt-free: open ``virtual:cornell``, calibrate, acquire, make a document.

It reproduces the paper's Fig. 6: the right wall of the Cornell-like box is the target,
acquired at 4th order on the simulated rig through :mod:`engine.workflow` (the same code the
``albedit capture`` command runs), and recolored from green to blue with
κ = (2.0, 0.125, 8.0). The scene's other targets are painted but not acquired. Everything is
recorded in a scratch session folder that "Save As" copies.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from app.model.document import Document
from app.model.files import unreachable_pixels
from engine.progress import checkpoint, report

DEMO_RIG = "virtual:cornell"
#: The target acquired in the demo and its κ (paper, Fig. 6: green (0.1, 0.8, 0.1) → blue (0.2, 0.1, 0.8)).
DEMO_TARGET = "right_wall"
DEMO_KAPPA = (2.0, 0.125, 8.0)
DEMO_ORDER = 4


def _stage(progress, name: str):
    """A progress callback that prefixes ``name`` to the engine's messages."""
    if progress is None:
        return None
    return lambda step, total, message: progress(step, total, f"{name}: {message}")


def open_demo(rig_name: str = DEMO_RIG, *, acquire: bool = True, folder=None, progress=None, should_stop=None,
              **rig_options):
    """Open a virtual rig and make the demo document.

    Parameters
    ----------
    rig_name : str
        A virtual rig with scene targets and ground truth.
    acquire : bool
        Calibrate the rig and acquire :data:`DEMO_TARGET` (a few seconds); False only takes
        the photograph and paints the scene targets.
    folder : str or Path, optional
        Where the scratch session is created (default: a new temporary folder).
    progress, should_stop
        :mod:`engine.progress` conventions; cancelling stops between captures.
    **rig_options
        Passed to :func:`devices.open_rig`; default ``ideal=True``.

    Returns
    -------
    document : Document
        Clean (nothing to save yet), scene targets painted; with ``acquire``, the right wall
        acquired and recolored as in Fig. 6, and the pixels the projector does not light
        marked unreachable (:func:`app.model.files.unreachable_pixels`).
    rig : devices.base.Rig
        Still open: its ``truth`` feeds the ground-truth views. Close it with the window.
    session : engine.session.Session or None
        The scratch session holding the calibration and captures (None without ``acquire``).
    """
    from devices import open_rig  # the app sits above devices; imported late to keep start-up light
    from engine.session import Session
    from engine.workflow import load_decomposition, run_calibration, run_capture

    rig_options.setdefault("ideal", True)
    report(progress, 0, 1, f"opening {rig_name}")
    rig = open_rig(rig_name, **rig_options)
    try:
        checkpoint(should_stop, "opening the demo")
        targets = {name: np.asarray(mask, bool) for name, mask in rig.targets.items()}
        if not acquire:
            frame = rig.camera.capture()
            doc = Document(np.asarray(frame.image, np.float32), source=rig_name, truth=rig.truth)
            for name, mask in targets.items():
                doc.add_target(name, mask)
            _finish(doc)
            return doc, rig, None
        root = Path(folder) if folder is not None else Path(tempfile.mkdtemp(prefix="albedit-demo-"))
        session = Session.create(root / "session", rig_name=rig_name, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution, metadata={"demo": True})
        calibration = run_calibration(rig, session, progress=_stage(progress, "calibrating"), should_stop=should_stop)
        name = DEMO_TARGET if DEMO_TARGET in targets else next(iter(targets))
        result = run_capture(rig, session, [(name, targets[name])], DEMO_ORDER,
                             progress=_stage(progress, f"acquiring {name!r}"), should_stop=should_stop)
        decomposition = load_decomposition(session)
        photo = np.ascontiguousarray(result.acquisition.observations[0], np.float32)
        doc = Document(photo, unreachable=unreachable_pixels(calibration), source=rig_name, truth=rig.truth)
        for other, mask in targets.items():  # the acquired target last: the end of its cascade
            if other != name:
                doc.add_target(other, mask)
        t = doc.add_target(name, targets[name])
        doc.set_acquisition([t.uid], decomposition, key=_cache_key(session))
        doc.set_kappa(t.uid, DEMO_KAPPA)
        _finish(doc)
        report(progress, 1, 1, "ready")
        return doc, rig, session
    except BaseException:
        rig.close()
        raise


def _cache_key(session) -> str:
    from engine.workflow import plan_key

    return plan_key(session)


def _finish(doc: Document) -> None:
    if doc.targets:
        doc.set_current(doc.targets[-1].uid)
    doc.history.clear()
    doc.mark_saved()
