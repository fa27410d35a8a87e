"""The virtual-rig demo document, Qt-free: photograph, scene targets pre-painted, ground truth."""

from __future__ import annotations

import numpy as np

from app.model import Document

DEMO_RIG = "virtual:cornell"


def open_demo(rig_name: str = DEMO_RIG, *, history=None, progress=None, should_stop=None, **rig_options):
    """Open a virtual rig and make a document of its photograph with its targets painted.

    Parameters
    ----------
    rig_name : str
        A rig with scene targets and ground truth, e.g. ``"virtual:cornell"``.
    history : History-like, optional
        Undo stack for the document.
    progress, should_stop
        :mod:`engine.progress` conventions (opening and the first capture can take seconds).
    **rig_options
        Passed to :func:`devices.open_rig`; default ``ideal=True``.

    Returns
    -------
    document : Document
        Clean (nothing to save), one target per scene target, in the scene's order.
    rig : devices.base.Rig
        Still open: its ``truth`` feeds the ground-truth views. Close it with the window.
    """
    from devices import open_rig  # the app depends on devices; imported late to keep start-up light
    from engine.progress import checkpoint, report

    rig_options.setdefault("ideal", True)
    report(progress, 0, 2, f"opening {rig_name}")
    rig = open_rig(rig_name, **rig_options)
    try:
        checkpoint(should_stop, "opening the demo")
        report(progress, 1, 2, "taking the photograph")
        frame = rig.camera.capture()
        doc = Document(np.asarray(frame.image, np.float32), history=history, source=rig_name,
                       truth=getattr(rig, "truth", None))
        for name, mask in rig.targets.items():
            doc.add_target(name, np.asarray(mask, bool))
        if doc.targets:
            doc.set_current(doc.targets[-1].uid)
        doc.history.clear()
        doc.mark_saved()
    except BaseException:
        rig.close()
        raise
    report(progress, 2, 2, "ready")
    return doc, rig
