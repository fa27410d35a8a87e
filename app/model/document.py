"""The editing model: photograph, targets (masks, κ, cascade order), acquisition and undo.

Qt-free. Widgets write the model; the model says what changed through psygnal signals
(:class:`~app.model.target.DocumentEvents`); every edit is a command on the undo :class:`~app.model.history.History`.

Vocabulary (DESIGN.md): a *target* is a set of camera pixels whose albedo is scaled by
*kappa* (κ, one factor per channel). Targets are kept in *cascade* order (paper, Sec. 4):
once a cascade has been acquired, the κ of every target but the last one shaped the light
emitted for the later ones, so they are locked; only the last target's κ stays free and is
the one :func:`engine.recolor.recolor` applies to the decomposition.

Over 500 lines on purpose: every edit of the document (masks, coverage, κ, order, acquisition,
noise reduction) is a command on one history, and the invariants they keep are checked here together.
"""

from __future__ import annotations

import uuid
from dataclasses import replace
from typing import Any

import numpy as np

from app.model import commands as cmd
from app.model.history import History
from app.model.target import KAPPA_MAX, KAPPA_MIN, PALETTE, BBox, DocumentEvents, Measurement, Target
from engine.checks import check_float_image, check_kappa, check_mask
from engine.edge import check_coverage, refine_mask
from engine.errors import InputError
from engine.trust import lamp_caution
from engine.workflow import check_targets

__all__ = ["BBox", "Document", "camera_mismatch", "KAPPA_MAX", "KAPPA_MIN", "Measurement", "PALETTE", "Target"]

def camera_mismatch(photograph_shape, camera_resolution) -> str:
    """Why a camera of ``camera_resolution`` (H, W) cannot measure targets painted on a photograph of
    ``photograph_shape`` (H, W), in words (``"the open photograph is 32×24, the camera 32×32"``), or ``""``.

    Targets are painted on the photograph's pixels: only a camera of its size can acquire them, and a
    session of another size cannot hold its edit.
    """
    (h, w), (ch, cw) = (int(v) for v in photograph_shape[:2]), (int(v) for v in camera_resolution[:2])
    return "" if (h, w) == (ch, cw) else f"the open photograph is {w}×{h}, the camera {cw}×{ch}"


class Document:
    """Everything the user edits, Qt-free.

    Parameters
    ----------
    photograph : (H, W, 3) float32
        Linear radiance, the original image (``obs[0]``).
    unreachable : (H, W) bool, optional
        Camera pixels the projector cannot light (shadowed, grazing, outside the projector
        frustum). Painting them is allowed and shown, but refused for acquisition.
    history : History-like, optional
        Undo stack; the app passes a QUndoStack adapter. Default: a Qt-free :class:`History`.
    source : str
        Where the photograph came from (rig name or path), for titles and metadata.
    truth : object, optional
        Ground truth with ``recolor([(mask, kappa), ...])`` (virtual rig only).

    Examples
    --------
    >>> doc = Document(np.zeros((4, 5, 3), np.float32))
    >>> t = doc.add_target("wall")
    >>> doc.set_kappa(t.uid, 2.0); doc.target(t.uid).kappa
    array([2., 2., 2.])
    >>> doc.history.undo(); doc.target(t.uid).kappa
    array([1., 1., 1.])
    """

    def __init__(self, photograph, *, unreachable=None, history=None, source: str = "", truth=None):
        self.photograph = check_float_image("photograph", photograph, ndim=3).astype(np.float32, copy=False)
        if self.photograph.shape[2] != 3:
            raise InputError(f"photograph must have 3 channels (H, W, 3), got shape {self.photograph.shape}")
        self.shape: tuple[int, int] = self.photograph.shape[:2]
        self.unreachable = None if unreachable is None else check_mask("unreachable", unreachable, self.shape).copy()
        self.events = DocumentEvents()
        self.history = history if history is not None else History()
        self.history.changed.connect(self._on_history_changed)
        self.source = source
        self.truth = truth
        self.targets: list[Target] = []
        self.current: int = -1
        self.acquisition: Measurement | None = None
        self._next_uid = 1
        self._gesture: tuple[int, np.ndarray] | None = None
        self._stroke: cmd.Stroke | None = None
        self._dirty_outside_history = False
        self._last_dirty = False
        self._trusted: dict[str, tuple[Any, str]] = {}  # acquisition key → (TrustedDecomposition or None, why not)

    def use_history(self, history) -> None:
        """Move to another (empty) undo stack, e.g. a QUndoStack adapter once on the UI thread."""
        was_dirty = self.is_dirty()
        self.history.changed.disconnect(self._on_history_changed)
        self.history = history
        history.clear()
        history.changed.connect(self._on_history_changed)
        self._dirty_outside_history = was_dirty
        self._emit_dirty()

    # ----------------------------------------------------------------- queries
    def target(self, uid: int) -> Target:
        """The target with ``uid``; InputError if there is none."""
        for t in self.targets:
            if t.uid == uid:
                return t
        raise InputError(f"no target with uid {uid}; targets are {[t.uid for t in self.targets]}")

    def index(self, uid: int) -> int:
        """Cascade position of target ``uid``."""
        return self.targets.index(self.target(uid))

    def by_name(self, name: str) -> Target:
        for t in self.targets:
            if t.name == name:
                return t
        raise InputError(f"no target named {name!r}; targets are {[t.name for t in self.targets]}")

    @property
    def decomposition(self):
        return None if self.acquisition is None else self.acquisition.decomposition

    def kappa_lock(self, uid: int) -> str:
        """Why κ of ``uid`` cannot change (empty string when it can)."""
        acq = self.acquisition
        if acq is None or uid not in acq.cascade[:-1]:
            return ""
        later = ", ".join(repr(self.target(u).name) for u in acq.cascade[acq.cascade.index(uid) + 1 :] if self._has(u))
        return (
            f"κ of {self.target(uid).name!r} is fixed: it shaped the light emitted while acquiring "
            f"{later or 'the later targets'} (cascade, paper Sec. 4). Discard the acquisition to change it."
        )

    def mask_lock(self, uid: int) -> str:
        """Why the mask of ``uid`` cannot change (empty string when it can)."""
        acq = self.acquisition
        if acq is None or uid not in acq.cascade:
            return ""
        return (
            f"the mask of {self.target(uid).name!r} was acquired: the measured decomposition belongs to it. "
            "Discard the acquisition to edit it."
        )

    def is_dirty(self) -> bool:
        """True when there are unsaved changes."""
        return self._dirty_outside_history or not self.history.is_clean()

    def unreachable_conflicts(self) -> dict[str, int]:
        """Painted pixels the projector cannot reach, per target name (only non-zero counts)."""
        if self.unreachable is None:
            return {}
        out = {}
        for t in self.targets:
            n = int(np.count_nonzero(t.mask & self.unreachable))
            if n:
                out[t.name] = n
        return out

    def camera_mismatch(self, camera_resolution) -> str:
        """Why a camera of ``camera_resolution`` cannot measure this photograph's targets, or ``""``
        (:func:`camera_mismatch`)."""
        return camera_mismatch(self.shape, camera_resolution)

    def lamp_cautions(self, uids=None) -> list[str]:
        """A line per target (default the included ones) that holds a light source
        (:func:`engine.trust.lamp_caution`): κ would scale the lamp's own light."""
        uids = [t.uid for t in self.acquisition_targets()] if uids is None else list(uids)
        found = (lamp_caution(self.target(u).name, self.photograph, self.target(u).acquired_mask()) for u in uids)
        return [line for line in found if line]

    def check_acquirable(self, uids=None) -> None:
        """Raise InputError if the targets cannot be acquired (empty, or unreachable pixels).

        Parameters
        ----------
        uids : sequence of int, optional
            The cascade to acquire, first to last; default the included targets in order.
        """
        uids = [t.uid for t in self.acquisition_targets()] if uids is None else list(uids)
        check_targets([(self.target(u).name, self.target(u).acquired_mask()) for u in uids], self.shape,
                      unreachable=self.unreachable)

    # ----------------------------------------------------------------- target list
    def add_target(self, name: str | None = None, mask=None, *, kappa=1.0, index: int | None = None) -> Target:
        """Add a target (undoable) and make it current. Returns it.

        ``mask`` is ``(H, W)`` bool, or float coverage in [0, 1] (a soft edge, :mod:`engine.edge`).
        """
        name = self._unique_name(name or f"target {len(self.targets) + 1}")
        coverage = None
        if mask is not None and np.asarray(mask).dtype.kind == "f":
            coverage = check_coverage("mask", mask, self.shape).copy()
            mask = coverage >= 0.5
        mask = np.zeros(self.shape, bool) if mask is None else check_mask("mask", mask, self.shape).copy()
        colour = self._free_colour()
        t = Target(self._next_uid, name, mask, check_kappa(kappa, 3), colour, coverage=coverage)
        self._next_uid += 1
        index = len(self.targets) if index is None else int(index)
        self.history.push(cmd.AddTarget(self, t, index))
        return t

    def remove_target(self, uid: int) -> None:
        """Delete a target (undoable). Acquired targets can't be removed."""
        if lock := self.mask_lock(uid):
            raise InputError(f"cannot delete: {lock}")
        self.history.push(cmd.RemoveTarget(self, self.target(uid), self.index(uid)))

    def rename_target(self, uid: int, name: str) -> None:
        """Rename (undoable). Names are unique and non-empty."""
        name = str(name).strip()
        t = self.target(uid)
        if name == t.name:
            return
        if not name:
            raise InputError("target name must not be empty")
        if any(o.name == name for o in self.targets if o.uid != uid):
            raise InputError(f"target name {name!r} is already used; choose another")
        self.history.push(cmd.Rename(self, uid, t.name, name))

    def move_target(self, uid: int, index: int) -> None:
        """Move target ``uid`` to cascade position ``index`` (undoable)."""
        old = self.index(uid)
        index = int(index)
        if not 0 <= index < len(self.targets):
            raise InputError(f"index must be in 0..{len(self.targets) - 1}, got {index}")
        if index == old:
            return
        if self.acquisition is not None:
            raise InputError("the cascade order was fixed by the acquisition; discard it to reorder targets")
        self.history.push(cmd.Move(self, uid, old, index))

    def set_included(self, uid: int, included: bool) -> None:
        """Include target ``uid`` in the next acquisition, or leave it out (undoable)."""
        if bool(included) != self.target(uid).included:
            self.history.push(cmd.Include(self, uid, included))

    def acquisition_targets(self) -> list[Target]:
        """The targets the next acquisition measures: the included ones, in cascade order."""
        return [t for t in self.targets if t.included]

    def set_current(self, uid: int) -> None:
        """Select the target that tools paint into (not an edit: no undo step)."""
        if uid != -1:
            self.target(uid)
        if uid != self.current:
            self.current = uid
            self.events.current.emit(uid)

    # ----------------------------------------------------------------- kappa
    def set_kappa(self, uid: int, kappa) -> None:
        """Set κ of target ``uid``: one undo step, or live inside a slider gesture."""
        if lock := self.kappa_lock(uid):
            raise InputError(lock)
        k = check_kappa(kappa, 3)
        t = self.target(uid)
        if np.array_equal(k, t.kappa):
            return
        if self._gesture is not None and self._gesture[0] == uid:
            self._mutate_kappa(uid, k)
        else:
            self.history.push(cmd.Kappa(self, uid, t.kappa.copy(), k))

    def begin_kappa_gesture(self, uid: int) -> None:
        """A slider drag starts: κ changes until :meth:`end_kappa_gesture` make one undo step."""
        self.end_kappa_gesture()
        self._gesture = (uid, self.target(uid).kappa.copy())

    def end_kappa_gesture(self) -> None:
        """Close the current slider gesture (no-op without one)."""
        if self._gesture is None:
            return
        uid, old = self._gesture
        self._gesture = None
        if self._has(uid) and not np.array_equal(old, self.target(uid).kappa):
            self.history.push(cmd.Kappa(self, uid, old, self.target(uid).kappa.copy()), applied=True)

    def reset_kappa(self, uid: int) -> None:
        """κ back to 1 (undoable)."""
        self.set_kappa(uid, 1.0)

    # ----------------------------------------------------------------- masks
    def begin_stroke(self, uid: int, *, soft: bool = False) -> None:
        """A drag starts painting ``uid``; :meth:`paint` calls accumulate into one undo step.

        ``soft``: the stroke paints coverage (:meth:`paint_soft`), so the target's edge
        becomes soft first (its coverage starts as the binary mask: nothing visible changes).
        """
        if lock := self.mask_lock(uid):
            raise InputError(lock)
        self.end_stroke()
        t = self.target(uid)
        if soft and t.coverage is None:
            t.coverage = t.mask.astype(np.float32)
        self._stroke = cmd.Stroke(uid)

    def paint(self, uid: int, bbox: BBox, stamp: np.ndarray, value: bool) -> int:
        """Set ``mask[bbox][stamp] = value``; returns the number of pixels that changed.

        Inside a stroke (:meth:`begin_stroke`) the old values are remembered for one undo step
        when the stroke ends; outside a stroke each call is its own undo step.
        """
        bbox = self._clip_bbox(bbox)
        if bbox is None:
            return 0
        y0, y1, x0, x1 = bbox
        stamp = np.asarray(stamp, bool)
        if stamp.shape != (y1 - y0, x1 - x0):
            raise InputError(f"stamp must have the bbox's shape {(y1 - y0, x1 - x0)}, got {stamp.shape}")
        t = self.target(uid)
        region = t.mask[y0:y1, x0:x1]
        change = stamp & (region != value)
        if t.coverage is not None:  # a soft edge: partly covered pixels change too
            change = stamp & (t.coverage[y0:y1, x0:x1] != np.float32(value))
        n = int(np.count_nonzero(change))
        if n == 0:
            return 0
        after = tuple(a[y0:y1, x0:x1].copy() for a in cmd.layers(t))
        for a in after:
            a[change] = value
        self._apply_stroke(uid, bbox, after, "Paint")
        self._warn_unreachable(t, bbox, change, value)
        return n

    def paint_soft(self, uid: int, bbox: BBox, weight: np.ndarray, add: bool) -> int:
        """Paint coverage: ``max(coverage, weight)`` (add) or ``min(coverage, 1 − weight)`` (erase).

        A feathered brush's stamp (``weight`` in [0, 1], the bbox's shape) makes the edge soft;
        the binary mask follows (``coverage >= 0.5``). One undo step inside a stroke, as :meth:`paint`.
        Returns the number of pixels whose coverage changed.
        """
        bbox = self._clip_bbox(bbox)
        if bbox is None:
            return 0
        y0, y1, x0, x1 = bbox
        weight = np.clip(np.asarray(weight, np.float32), 0, 1)
        if weight.shape != (y1 - y0, x1 - x0):
            raise InputError(f"weight must have the bbox's shape {(y1 - y0, x1 - x0)}, got {weight.shape}")
        t = self.target(uid)
        if t.coverage is None:
            if lock := self.mask_lock(uid):
                raise InputError(lock)
            t.coverage = t.mask.astype(np.float32)
        old = t.coverage[y0:y1, x0:x1]
        new = np.maximum(old, weight) if add else np.minimum(old, 1 - weight)
        change = new != old
        n = int(np.count_nonzero(change))
        if n == 0:
            return 0
        mask = t.mask[y0:y1, x0:x1]
        self._apply_stroke(uid, bbox, (new >= 0.5, new), "Paint")
        self._warn_unreachable(t, bbox, (new >= 0.5) & ~mask, True)
        return n

    def refine_edge(self, uid: int) -> int:
        """Refine the target's edge from the photograph (:func:`engine.edge.refine_mask`), one undo step.

        Pixels on the binary mask's boundary get the fraction of them on the target (never
        more than the other targets leave of them); returns how many pixels are partly target
        afterwards.
        """
        if lock := self.mask_lock(uid):
            raise InputError(lock)
        t = self.target(uid)
        if not t.mask.any():
            raise InputError(f"{t.name!r} is empty: paint it before refining its edge")
        claimed = np.zeros(self.shape, np.float32)
        for other in self.targets:  # touching targets share their boundary pixels
            if other.uid != uid:
                claimed += other.mask if other.coverage is None else other.coverage
        coverage = refine_mask(t.mask, self.photograph, claimed=np.minimum(claimed, 1.0))
        bbox = (0, self.shape[0], 0, self.shape[1])
        if t.coverage is None:
            t.coverage = t.mask.astype(np.float32)
        before = tuple(a.copy() for a in cmd.layers(t))
        if not np.array_equal(before[1], coverage):
            self.history.push(cmd.MaskEdit(self, uid, bbox, before, (coverage >= 0.5, coverage), "Refine edge"))
        return t.edge_pixels()

    def _apply_stroke(self, uid: int, bbox: BBox, after: tuple[np.ndarray, ...], verb: str) -> None:
        """Write ``after`` (a region per :func:`~app.model.commands.layers`) into the stroke, else as an undo step."""
        t = self.target(uid)
        y0, y1, x0, x1 = bbox
        if self._stroke is None or self._stroke.uid != uid:
            if lock := self.mask_lock(uid):
                raise InputError(lock)
            before = tuple(a[y0:y1, x0:x1].copy() for a in cmd.layers(t))
            self.history.push(cmd.MaskEdit(self, uid, bbox, before, after, verb))
            return
        self._stroke.remember(cmd.layers(t), bbox)
        for array, values in zip(cmd.layers(t), after, strict=True):
            array[y0:y1, x0:x1] = values
        self.events.mask.emit(uid, bbox)

    def end_stroke(self) -> None:
        """Close the stroke: one undo step with its bounding box and old values."""
        stroke, self._stroke = self._stroke, None
        if stroke is None or stroke.bbox is None or not self._has(stroke.uid):
            return
        y0, y1, x0, x1 = stroke.bbox
        after = tuple(a[y0:y1, x0:x1].copy() for a in cmd.layers(self.target(stroke.uid)))
        if all(np.array_equal(a, b) for a, b in zip(after, stroke.before, strict=True)):
            return
        self.history.push(cmd.MaskEdit(self, stroke.uid, stroke.bbox, stroke.before, after, "Paint"), applied=True)

    def set_mask_region(self, uid: int, bbox: BBox, values: np.ndarray, text: str = "Edit mask") -> None:
        """Replace ``mask[bbox]`` with ``values`` as one undo step (polygon, fill, clear).

        Boolean ``values`` are binary (a soft edge's coverage there becomes 0/1); float values
        are coverage in [0, 1] (the edge becomes soft, the mask is ``values >= 0.5``).
        """
        if lock := self.mask_lock(uid):
            raise InputError(lock)
        y0, y1, x0, x1 = bbox
        t = self.target(uid)
        if np.asarray(values).dtype.kind == "f" and t.coverage is None:
            t.coverage = t.mask.astype(np.float32)  # the same mask: nothing visible changes
        before = tuple(a[y0:y1, x0:x1].copy() for a in cmd.layers(t))
        if np.asarray(values).dtype.kind == "f":
            coverage = np.clip(np.asarray(values, np.float32), 0, 1)
            values = coverage >= 0.5
        else:
            values = np.asarray(values, bool)
            coverage = values.astype(np.float32)
        if values.shape != before[0].shape:
            raise InputError(f"values must have the bbox's shape {before[0].shape}, got {values.shape}")
        after = (values.copy(),) + ((coverage,) if t.coverage is not None else ())
        if all(np.array_equal(a, b) for a, b in zip(after, before, strict=True)):
            return
        self.history.push(cmd.MaskEdit(self, uid, bbox, before, after, text))
        self._warn_unreachable(t, bbox, values & ~before[0], True)

    def clear_mask(self, uid: int) -> None:
        """Empty the mask (one undo step storing only the painted bounding box)."""
        bbox = _nonzero_bbox(self.target(uid).mask)
        if bbox is not None:
            y0, y1, x0, x1 = bbox
            self.set_mask_region(uid, bbox, np.zeros((y1 - y0, x1 - x0), bool), "Clear")

    def invert_mask(self, uid: int) -> None:
        """Invert the mask (one undo step; stores no pixels: inverting is its own inverse)."""
        if lock := self.mask_lock(uid):
            raise InputError(lock)
        self.target(uid)
        self.history.push(cmd.Invert(self, uid))
        t = self.target(uid)
        self._warn_unreachable(t, (0, self.shape[0], 0, self.shape[1]), t.mask, True)

    # ----------------------------------------------------------------- acquisition
    def set_acquisition(self, cascade, decomposition, *, key: str | None = None, noise_aware: bool = True) -> None:
        """Record a measured cascade (one undo step: undoing it is Discard Acquisition's, and the edits
        before it, masks included, can then be undone too; the history is linear, so a redo reaches the
        acquisition again only with the masks it measured).

        Parameters
        ----------
        cascade : sequence of int
            Target uids, first to last, as acquired.
        decomposition : engine.decompose.Decomposition
            Decomposition of the last target; its ``target`` is that target's mask, or the part
            of it the projector could reach (acquisition drops unreachable pixels).
        key : str, optional
            Id of the measurement (default: a new random one).
        noise_aware : bool
            Recolor with the noise-aware recolor once its data is there (:meth:`set_trusted`).
        """
        cascade = tuple(int(u) for u in cascade)
        if not cascade:
            raise InputError("cascade must name at least one target")
        if len(set(cascade)) != len(cascade):
            raise InputError(f"cascade names a target twice: {list(cascade)}")
        for u in cascade:
            self.target(u)
        last = self.target(cascade[-1])
        dshape = tuple(np.shape(decomposition.target))
        if dshape != self.shape:
            raise InputError(f"decomposition is {dshape}, the photograph is {self.shape}: they must match")
        outside = int(np.count_nonzero(np.asarray(decomposition.target) & ~last.mask))
        if outside:
            raise InputError(
                f"decomposition.target has {outside} pixels outside the mask of {last.name!r}, the last cascade "
                "target; it must be that mask (or the part of it the projector could reach)"
            )
        self.end_stroke()
        self.end_kappa_gesture()
        measured = Measurement(
            cascade,
            tuple(self.target(u).kappa.copy() for u in cascade),
            tuple(self.target(u).mask.copy() for u in cascade),
            decomposition,
            key or f"decomposition-{uuid.uuid4().hex[:12]}",
            noise_aware=bool(noise_aware),
        )
        names = ", ".join(repr(self.target(u).name) for u in cascade)
        self.history.push(cmd.SetMeasurement(self, self.acquisition, measured, f"Acquire {names}"))
        self._emit_dirty()

    def set_noise_reduction(self, radius: int, decomposition=None) -> None:
        """Use ``decomposition`` — the measured one noise-reduced with ``radius`` — for recoloring.

        One undo step; ``radius`` 0 goes back to the measured decomposition and needs none.

        Raises
        ------
        InputError
            Nothing acquired, a negative radius, a missing decomposition for ``radius`` > 0, or
            one of another shape or target.
        """
        acq = self.acquisition
        if acq is None:
            raise InputError("nothing is acquired yet: noise reduction filters a decomposition")
        radius = int(radius)
        if radius < 0:
            raise InputError(f"noise reduction radius must be >= 0 pixels, got {radius}")
        if radius == 0:
            decomposition = acq.raw
        elif decomposition is None:
            raise InputError("noise reduction needs the filtered decomposition")
        elif decomposition.components.shape != acq.raw.components.shape or not np.array_equal(
                decomposition.target, acq.raw.target):
            raise InputError("the filtered decomposition does not match the measured one (shape or target)")
        new = replace(acq, decomposition=decomposition, denoise=radius, measured=None if radius == 0 else acq.raw)
        text = f"Noise reduction {radius} px" if radius else "Noise reduction off"
        self.history.push(cmd.SetMeasurement(self, acq, new, text))

    def set_noise_aware(self, on: bool) -> None:
        """Recolor noise-aware (:mod:`engine.trust`) or plainly (:func:`engine.recolor.recolor`); one undo step.

        Raises
        ------
        InputError
            Nothing acquired.
        """
        acq = self.acquisition
        if acq is None:
            raise InputError("nothing is acquired yet: the noise-aware recolor recolors an acquisition")
        if on and acq.key in self._trusted and self._trusted[acq.key][0] is None:
            del self._trusted[acq.key]  # asked for again: try again (a cancelled preparation, say)
        if bool(on) != acq.noise_aware:
            self.history.push(cmd.SetMeasurement(self, acq, replace(acq, noise_aware=bool(on)),
                                                 "Noise-aware recolor" if on else "Plain recolor"))

    def set_trusted(self, key: str, trusted, problem: str = "") -> None:
        """The noise-aware data of acquisition ``key`` (:func:`engine.workflow.load_trusted`), or why there is none.

        Not an edit (computed data, like a decomposition read from the cache): no undo step.
        ``trusted`` None with ``problem`` (one line) records that this acquisition can only
        be recolored plainly.
        """
        self._trusted[str(key)] = (trusted, str(problem))
        if self.acquisition is not None and self.acquisition.key == key:
            self.events.acquisition.emit()

    def needs_trusted(self) -> bool:
        """The acquisition asks for the noise-aware recolor and its data was neither prepared nor refused."""
        acq = self.acquisition
        return acq is not None and acq.noise_aware and acq.key not in self._trusted

    @property
    def trusted(self):
        """The noise-aware data the acquisition is recolored with now, or None (recolored plainly)."""
        acq = self.acquisition
        if acq is None or not acq.noise_aware:
            return None
        return self._trusted.get(acq.key, (None, ""))[0]

    def recolor_note(self) -> str:
        """One line for the status bar: which recolor is shown, and why when it is not the one asked for."""
        acq = self.acquisition
        if acq is None:
            return ""
        if not acq.noise_aware:
            return "plain recolor (View ▸ Noise-Aware Recolor is off)"
        trusted, problem = self._trusted.get(acq.key, (None, ""))
        if trusted is not None:
            return "noise-aware recolor"
        return f"plain recolor: {problem}" if problem else "plain recolor for now"

    def discard_acquisition(self) -> None:
        """Forget the measurement (one undo step): every κ and mask becomes editable again."""
        if self.acquisition is not None:
            self.history.push(cmd.SetMeasurement(self, self.acquisition, None, "Discard acquisition"))

    def recolor_kappa(self) -> np.ndarray:
        """κ the decomposition is recolored with: the last cascade target's (ones without one)."""
        if self.acquisition is None:
            return np.ones(3)
        uid = self.acquisition.cascade[-1]
        return self.target(uid).kappa.copy() if self._has(uid) else np.ones(3)

    def mark_saved(self) -> None:
        """The document was written: the current state is clean."""
        self._dirty_outside_history = False
        self.history.set_clean()
        self._emit_dirty()

    # ----------------------------------------------------------------- internals
    def _has(self, uid: int) -> bool:
        return any(t.uid == uid for t in self.targets)

    def _unique_name(self, name: str) -> str:
        names = {t.name for t in self.targets}
        base, i, out = name, 2, name
        while out in names:
            out = f"{base} ({i})"
            i += 1
        return out

    def _free_colour(self) -> tuple[int, int, int]:
        used = [t.colour for t in self.targets]
        for c in PALETTE:
            if c not in used:
                return c
        return PALETTE[(self._next_uid - 1) % len(PALETTE)]

    def _clip_bbox(self, bbox: BBox) -> BBox | None:
        y0, y1, x0, x1 = (int(v) for v in bbox)
        h, w = self.shape
        y0, x0, y1, x1 = max(y0, 0), max(x0, 0), min(y1, h), min(x1, w)
        if y0 >= y1 or x0 >= x1:
            return None
        return y0, y1, x0, x1

    # The commands (app.model.commands) change the document through these, which keep it
    # consistent before any signal goes out.
    def _mutate_kappa(self, uid: int, kappa: np.ndarray) -> None:
        self.target(uid).kappa = np.array(kappa, dtype=np.float64)
        self.events.kappa.emit(uid, self.target(uid).kappa.copy())

    def _mutate_target(self, uid: int, **fields) -> None:
        t = self.target(uid)
        for k, v in fields.items():
            setattr(t, k, v)
        self.events.targets.emit()

    def _mutate_insert(self, t: Target, index: int) -> None:
        """Put ``t`` back at ``index`` and make it current."""
        self.targets.insert(index, t)
        self.current = t.uid
        self.events.targets.emit()
        self.events.current.emit(t.uid)

    def _mutate_remove(self, t: Target, fallback: int | None) -> None:
        """Take ``t`` out; if it was current, ``fallback`` (or its neighbour) becomes current first."""
        index = self.targets.index(t)
        self.targets.remove(t)
        changed = self.current == t.uid
        if changed:
            if fallback is not None and self._has(fallback):
                self.current = fallback
            else:
                self.current = self.targets[min(index, len(self.targets) - 1)].uid if self.targets else -1
        self.events.targets.emit()
        if changed:
            self.events.current.emit(self.current)

    def _mutate_measurement(self, measurement: Measurement | None) -> None:
        self.acquisition = measurement
        self.events.acquisition.emit()

    def _warn_unreachable(self, t: Target, bbox: BBox, added: np.ndarray, value: bool) -> None:
        if self.unreachable is None or not value:
            return
        y0, y1, x0, x1 = bbox
        n = int(np.count_nonzero(added & self.unreachable[y0:y1, x0:x1]))
        if n:
            self.events.warning.emit(
                f"{n} pixels of {t.name!r} are not reachable by the projector: shown hatched, "
                "they will be refused for acquisition"
            )

    def _on_history_changed(self) -> None:
        self._emit_dirty()

    def _emit_dirty(self) -> None:
        d = self.is_dirty()
        if d != self._last_dirty:
            self._last_dirty = d
            self.events.dirty.emit(d)


def _nonzero_bbox(mask: np.ndarray) -> BBox | None:
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
