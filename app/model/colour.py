"""Colours in the editing model: what the Albedo panel shows and how colour requests become κ. Qt-free.

The panel shows the current target's colour as a swatch, its absolute albedo (or why it is
relative), and the κ range physics allows; the artist picks a colour, types one or an
albedo, or uses the eyedropper on the photograph or on a reference picture. Each request
becomes κ through :class:`engine.target_colour.TargetColour` (the same as ``albedit recolor``)
and is applied to the document as one undo step. Impossible requests raise
:class:`engine.errors.InputError` with the reason and change nothing; recolors the captured
order cannot follow are applied and return a warning.
"""

from __future__ import annotations

import numpy as np

from app.model.document import KAPPA_MAX, Document
from engine.checks import check_kappa
from engine.colour import parse_colour, pick_colour, to_hex
from engine.errors import InputError
from engine.session import Session
from engine.target_colour import TargetColour
from engine.workflow import RELATIVE, target_albedo, target_colour, target_direct

__all__ = ["ColourEditor", "linked_kappa", "session_colours"]

#: The top of the κ range when nothing measured bounds it.
UNBOUNDED = 16.0


def linked_kappa(kappa, channel: int, value: float, *, linked: bool = True, low: float = 0.0,
                 high=KAPPA_MAX) -> np.ndarray:
    """κ after setting ``channel`` to ``value``: alone, or with every channel by the same factor.

    A linked change stops where the first channel reaches ``low`` or ``high``, so the ratios
    between the channels (the hue of the change) never change.

    Parameters
    ----------
    kappa : (3,) float
        κ now.
    channel : int
        0, 1 or 2 (R, G, B).
    value : float
        The new κ of that channel, ≥ 0.
    linked : bool
        Move every channel by one factor (a channel at 0 moves alone: there is no ratio to keep).
    low : float
        Bottom of the range (the log slider's 1/16; 0 for typed values).
    high : float or (3,) float
        Top of the range per channel (the slider's 16, or the κ ceiling of
        :meth:`ColourEditor.kappa_range`).

    Returns
    -------
    (3,) float64

    Examples
    --------
    >>> linked_kappa([1.0, 2.0, 4.0], 0, 2.0).tolist()
    [2.0, 4.0, 8.0]
    >>> linked_kappa([1.0, 2.0, 4.0], 0, 2.0, high=[10, 10, 6]).tolist()
    [1.5, 3.0, 6.0]
    >>> linked_kappa([2.0, 0.125, 8.0], 2, 1.0, low=1 / 16).tolist()  # G stops at 1/16: B can only halve
    [1.0, 0.0625, 4.0]
    >>> linked_kappa([2.0, 0.125, 8.0], 2, 1.0, linked=False).tolist()
    [2.0, 0.125, 1.0]
    """
    k = check_kappa(kappa, 3).copy()
    if channel not in (0, 1, 2):
        raise InputError(f"channel must be 0, 1 or 2 (R, G, B), got {channel!r}")
    value = float(check_kappa(value, 1)[0])
    if not linked or k[channel] <= 0:
        k[channel] = value
        return k
    top = np.broadcast_to(np.asarray(high, np.float64), (3,))
    positive = k > 0
    lo = float(low) / k[positive].min()
    hi = float(np.min(top[positive] / k[positive]))
    factor = min(max(value / k[channel], lo), hi)
    return k * factor


def session_colours(document: Document, session: Session | None) -> dict[int, TargetColour]:
    """What is known of each acquired target's colour, by target uid.

    The free (last) target of the acquisition gets its decomposition, every acquired target
    its D and, when a colour checker calibrated ``session``, its absolute albedo. Without a
    session (a photograph opened alone, the demo before saving) only the free target's
    decomposition is known.
    """
    acq = document.acquisition
    if acq is None:
        return {}
    free = acq.cascade[-1]
    if session is None:
        return {free: TargetColour(acq.raw)}
    out = {}
    for uid, mask in zip(acq.cascade, acq.masks, strict=True):
        if uid == free:
            out[uid] = target_colour(session, acq.raw, mask)
            continue
        direct = target_direct(session, mask)
        try:
            albedo, relative = target_albedo(session, mask, direct), ""
        except InputError as exc:
            albedo, relative = None, str(exc)
        out[uid] = TargetColour(None, direct=direct, albedo=albedo, relative=relative)
    return out


class ColourEditor:
    """The Albedo panel's colour controls on a document.

    Parameters
    ----------
    document : Document
    colours : dict of int to TargetColour
        What is known of each acquired target's colour (:func:`session_colours`).

    Attributes
    ----------
    keep_luminance : bool
        Colour requests change hue and chroma only.
    """

    def __init__(self, document: Document, colours: dict[int, TargetColour]):
        self.doc = document
        self.colours = dict(colours)
        self.keep_luminance = False

    # ------------------------------------------------------------------ what the panel shows

    def colour(self, uid: int) -> TargetColour:
        """What is known of target ``uid``'s colour; InputError when it cannot be recolored by colour."""
        acq = self.doc.acquisition
        if acq is None or uid != acq.cascade[-1] or uid not in self.colours:
            name = self.doc.target(uid).name
            raise InputError(f"{name!r} has no measured colour: colours are chosen for the acquired target whose "
                             "κ is free (acquire it first)")
        return self.colours[uid]

    def swatch(self, uid: int, *, exposure: float = 0.0) -> str:
        """``"#rrggbb"`` of the target's colour with its κ now, shown at ``exposure`` stops."""
        return to_hex(self.colour(uid).colour(self.doc.target(uid).kappa), exposure=exposure)

    def albedo_text(self, uid: int) -> str:
        """The target's absolute albedo now and before recoloring, or why albedo is relative."""
        c = self.colour(uid)
        kappa = self.doc.target(uid).kappa
        if c.albedo is None:
            return c.relative or RELATIVE
        now = ", ".join(f"{v:.3f}" for v in c.new_albedo(kappa))
        was = ", ".join(f"{v:.3f}" for v in c.albedo)
        return f"Absolute albedo {now} (measured {was})"

    def kappa_range(self, uid: int) -> tuple[float, np.ndarray]:
        """``(low, high)`` of the κ controls: 0 (black) up to the ceiling per channel.

        The ceiling is ``1 / albedo`` with a colour checker (beyond it is impossible), else the
        estimated divergence of the interreflection series; never below the κ set now (a saved
        edit stays visible), and 16 where nothing bounds it.
        """
        c = self.colour(uid)
        top = np.where(np.isfinite(c.ceiling()), c.ceiling(), UNBOUNDED)
        return 0.0, np.maximum(top, self.doc.target(uid).kappa)

    def check(self, uid: int, kappa) -> str:
        """InputError for an impossible κ, else the warning for it (``""`` when the recolor converges)."""
        return self.colour(uid).check(kappa)

    # ------------------------------------------------------------------ requests

    def set_kappa(self, uid: int, kappa) -> str:
        """Apply ``kappa`` (one undo step) after checking it; returns the convergence warning."""
        k = check_kappa(kappa, 3)
        warning = self.check(uid, k)
        self.doc.set_kappa(uid, k)
        return warning

    def request_colour(self, uid: int, colour, *, exposure: float = 0.0) -> str:
        """The target takes a colour: text (``"#3355cc"``, ``"lab:…"``, …) or linear RGB meant at ``exposure`` stops."""
        wanted = parse_colour(colour) if isinstance(colour, str) else np.asarray(colour, np.float64)
        kappa = self.colour(uid).for_colour(wanted / 2.0 ** float(exposure), keep_luminance=self.keep_luminance)
        return self.set_kappa(uid, kappa)

    def request_albedo(self, uid: int, albedo) -> str:
        """The target takes an absolute albedo (refused without a colour checker, and for 1 or more)."""
        return self.set_kappa(uid, self.colour(uid).for_albedo(albedo))

    def pick(self, uid: int, x: float, y: float, *, radius: int = 2) -> str:
        """The eyedropper on the photograph at pixel ``(x, y)``.

        On another acquired target whose D was measured, the target takes that surface's
        albedo (its direct component, as the paper matches papers in Fig. 7); elsewhere, the
        colour the photograph shows there (which includes the light where it stands and its
        own interreflections: approximate).
        """
        col, row = int(round(float(x))), int(round(float(y)))
        h, w = self.doc.shape
        if not (0 <= col < w and 0 <= row < h):
            raise InputError(f"the point ({x}, {y}) is outside the {w}×{h} photograph")
        for other, known in self.colours.items():
            if other != uid and known.direct is not None and self.doc.target(other).mask[row, col]:
                return self.set_kappa(uid, self.colour(uid).to_match(known, keep_luminance=self.keep_luminance))
        seen = pick_colour(self.doc.photograph, col, row, radius=radius)
        return self.set_kappa(uid, self.colour(uid).for_seen(seen, keep_luminance=self.keep_luminance))

    def pick_reference(self, uid: int, image, x: float, y: float, *, encoded: bool = True, radius: int = 2,
                       exposure: float = 0.0) -> str:
        """The eyedropper on a reference picture (sRGB-encoded unless ``encoded`` is False): a colour from elsewhere."""
        seen = pick_colour(image, x, y, radius=radius, encoded=encoded)
        return self.request_colour(uid, seen, exposure=exposure)
