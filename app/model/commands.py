"""The undo commands of the editing model (one class per kind of edit), Qt-free.

Each command has ``text`` (shown in the Edit menu), ``redo()`` and ``undo()``, and changes a
:class:`~app.model.document.Document` only through its ``_mutate_*`` helpers, which keep the
document consistent *before* any signal goes out (a listener never sees a current target that
is no longer in the list).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from app.model.document import Document
    from app.model.target import BBox, Measurement, Target


class Stroke:
    """Bounding box and old values of everything one drag touched (napari's paint atom)."""

    def __init__(self, uid: int):
        self.uid = uid
        self.bbox: BBox | None = None
        self.before: np.ndarray | None = None

    def remember(self, mask: np.ndarray, bbox: BBox) -> None:
        """Grow the saved region to cover ``bbox`` before ``mask[bbox]`` is modified."""
        if self.bbox is None:
            y0, y1, x0, x1 = bbox
            self.bbox, self.before = bbox, mask[y0:y1, x0:x1].copy()
            return
        (a0, a1, b0, b1), (c0, c1, d0, d1) = self.bbox, bbox
        new = (min(a0, c0), max(a1, c1), min(b0, d0), max(b1, d1))
        if new == self.bbox:
            return
        y0, y1, x0, x1 = new
        # Outside the old box nothing was touched yet, so the mask still holds the old values.
        before = mask[y0:y1, x0:x1].copy()
        before[a0 - y0 : a1 - y0, b0 - x0 : b1 - x0] = self.before
        self.bbox, self.before = new, before


class MaskEdit:
    def __init__(self, doc: Document, uid: int, bbox: BBox, before, after, verb: str):
        self.doc, self.uid, self.bbox, self.before, self.after = doc, uid, bbox, before, after
        self.text = f"{verb} {doc.target(uid).name!r}"

    def _set(self, values) -> None:
        y0, y1, x0, x1 = self.bbox
        self.doc.target(self.uid).mask[y0:y1, x0:x1] = values
        self.doc.events.mask.emit(self.uid, self.bbox)

    def redo(self) -> None:
        self._set(self.after)

    def undo(self) -> None:
        self._set(self.before)


class Invert:
    def __init__(self, doc: Document, uid: int):
        self.doc, self.uid = doc, uid
        self.text = f"Invert {doc.target(uid).name!r}"

    def redo(self) -> None:
        t = self.doc.target(self.uid)
        np.logical_not(t.mask, out=t.mask)
        self.doc.events.mask.emit(self.uid, (0, self.doc.shape[0], 0, self.doc.shape[1]))

    undo = redo


class Kappa:
    def __init__(self, doc: Document, uid: int, old, new):
        self.doc, self.uid, self.old, self.new = doc, uid, np.array(old), np.array(new)
        self.text = f"Albedo {doc.target(uid).name!r}"

    def redo(self) -> None:
        self.doc._mutate_kappa(self.uid, self.new)

    def undo(self) -> None:
        self.doc._mutate_kappa(self.uid, self.old)


class AddTarget:
    def __init__(self, doc: Document, target: Target, index: int):
        self.doc, self.t, self.i = doc, target, index
        self.previous = doc.current
        self.text = f"Add target {target.name!r}"

    def redo(self) -> None:
        self.doc._mutate_insert(self.t, self.i)

    def undo(self) -> None:
        self.doc._mutate_remove(self.t, self.previous)


class RemoveTarget:
    def __init__(self, doc: Document, target: Target, index: int):
        self.doc, self.t, self.i = doc, target, index
        self.text = f"Delete target {target.name!r}"

    def redo(self) -> None:
        self.doc._mutate_remove(self.t, None)

    def undo(self) -> None:
        self.doc._mutate_insert(self.t, self.i)


class Rename:
    def __init__(self, doc: Document, uid: int, old: str, new: str):
        self.doc, self.uid, self.old, self.new = doc, uid, old, new
        self.text = f"Rename {old!r} to {new!r}"

    def redo(self) -> None:
        self.doc._mutate_target(self.uid, name=self.new)

    def undo(self) -> None:
        self.doc._mutate_target(self.uid, name=self.old)


class Include:
    def __init__(self, doc: Document, uid: int, included: bool):
        self.doc, self.uid, self.included = doc, uid, bool(included)
        verb = "Include" if included else "Leave out"
        self.text = f"{verb} {doc.target(uid).name!r} in the acquisition"

    def redo(self) -> None:
        self.doc._mutate_target(self.uid, included=self.included)

    def undo(self) -> None:
        self.doc._mutate_target(self.uid, included=not self.included)


class Move:
    def __init__(self, doc: Document, uid: int, old: int, new: int):
        self.doc, self.uid, self.old, self.new = doc, uid, old, new
        self.text = f"Move {doc.target(uid).name!r}"

    def _to(self, i: int) -> None:
        t = self.doc.target(self.uid)
        self.doc.targets.remove(t)
        self.doc.targets.insert(i, t)
        self.doc.events.targets.emit()

    def redo(self) -> None:
        self._to(self.new)

    def undo(self) -> None:
        self._to(self.old)


class SetMeasurement:
    """Replace the document's measurement (noise reduction applied or removed, acquisition discarded)."""

    def __init__(self, doc: Document, old: Measurement | None, new: Measurement | None, text: str):
        self.doc, self.old, self.new, self.text = doc, old, new, text

    def redo(self) -> None:
        self.doc._mutate_measurement(self.new)

    def undo(self) -> None:
        self.doc._mutate_measurement(self.old)
