"""The parts of an edit, Qt-free: targets, the measurement, and the signals of a document.

:class:`~app.model.document.Document` holds them and changes them through undo commands
(:mod:`app.model.commands`); this module only defines what they are.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from psygnal import Signal, SignalGroup

from engine.edge import edge, is_soft

#: Slider range of κ (log scale), as in the issue: 1/16 … 16.
KAPPA_MIN = 1.0 / 16.0
KAPPA_MAX = 16.0

#: Overlay colours (RGB) handed to new targets in turn.
PALETTE: tuple[tuple[int, int, int], ...] = (
    (255, 70, 70),
    (60, 150, 255),
    (255, 205, 0),
    (60, 215, 120),
    (200, 90, 255),
    (255, 135, 20),
    (0, 215, 215),
    (255, 90, 185),
)

BBox = tuple[int, int, int, int]  # (y0, y1, x0, x1), half-open, camera pixels


@dataclass
class Target:
    """One target: a mask in camera pixels (binary, or soft along its edge) and its albedo scale.

    Attributes
    ----------
    uid : int
        Stable identity (names change, positions change).
    name : str
        Display name: any non-empty text (files store masks under names of their own).
    mask : (H, W) bool
        Owned by the document; edit it only through :class:`Document`. With a soft edge it is
        the pixels at least half on the target (``coverage >= 0.5``).
    kappa : (3,) float64
        Per-channel albedo scale κ.
    colour : (3,) int
        Overlay colour, RGB 0..255.
    included : bool
        Whether the next acquisition measures it (its place in the cascade is its place in the list).
    coverage : (H, W) float32 or None
        The fraction of each pixel on the target (:mod:`engine.edge`), once a feathered brush
        or Refine Edge made the edge soft; None while the mask is binary. Owned by the document.
    """

    uid: int
    name: str
    mask: np.ndarray
    kappa: np.ndarray = field(default_factory=lambda: np.ones(3))
    colour: tuple[int, int, int] = PALETTE[0]
    included: bool = True
    coverage: np.ndarray | None = None

    def acquired_mask(self) -> np.ndarray:
        """What acquisition measures: the soft mask when some pixel is partly target, else the binary mask.

        The target's own array, not a copy (read it, never write it).
        """
        if self.coverage is not None and is_soft(self.coverage):
            return self.coverage
        return self.mask

    def edge_pixels(self) -> int:
        """Pixels partly on the target (0 < coverage < 1)."""
        return 0 if self.coverage is None else int(np.count_nonzero(edge(self.coverage)))


@dataclass(frozen=True)
class Measurement:
    """What was measured: the cascade (target uids, first to last) and the decomposition.

    ``decomposition`` is the last target's decomposition, computed from observations that
    already carry the earlier targets' κ (paper, Algorithm 1); ``kappas`` are those κ.
    ``masks`` are the acquired masks (copies); ``key`` names the measurement (session cache).
    With noise reduction (``denoise`` > 0, :func:`engine.denoise.denoise_components` of that
    radius) ``decomposition`` is the filtered one and ``measured`` the one measured.
    ``noise_aware``: recolor with :func:`engine.trust.recolor_trusted` once its data is ready
    (:meth:`app.model.document.Document.set_trusted`), else plainly.
    """

    cascade: tuple[int, ...]
    kappas: tuple[np.ndarray, ...]
    masks: tuple[np.ndarray, ...]
    decomposition: Any
    key: str
    denoise: int = 0
    measured: Any = None
    noise_aware: bool = True

    @property
    def raw(self):
        """The decomposition as measured (before noise reduction)."""
        return self.decomposition if self.measured is None else self.measured


class DocumentEvents(SignalGroup):
    """Signals of a :class:`Document` (all emitted on the thread that edits it)."""

    #: targets added, removed, renamed, reordered, included or left out
    targets = Signal()
    #: mask of target ``uid`` changed inside ``bbox`` (y0, y1, x0, x1)
    mask = Signal(int, object)
    #: κ of target ``uid`` changed
    kappa = Signal(int, object)
    #: the current (selected) target changed: uid or -1
    current = Signal(int)
    #: acquisition / decomposition replaced or discarded
    acquisition = Signal()
    #: a message for the user about a harmless but notable edit (e.g. unreachable pixels)
    warning = Signal(str)
    #: saved / modified state flipped
    dirty = Signal(bool)
