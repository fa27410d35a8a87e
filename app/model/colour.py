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

from app.model.document import KAPPA_MIN, Document
from engine.checks import check_kappa
from engine.colour import parse_colour, pick_colour, to_hex
from engine.errors import InputError
from engine.session import Session
from engine.target_colour import TargetColour
from engine.workflow import RELATIVE, target_albedo, target_colour, target_direct

__all__ = ["ColourEditor", "linked_kappa", "session_colours"]

#: The top of the κ range when nothing measured bounds it.
UNBOUNDED = 16.0


def linked_kappa(kappa, channel: int, value: float, *, ceiling=None) -> np.ndarray:
    """κ after setting ``channel`` to ``value`` with the channels linked: their ratio is kept.

    Parameters
    ----------
    kappa : (3,) float
        κ now.
    channel : int
        0, 1 or 2 (R, G, B).
    value : float
        The new κ of that channel, ≥ 0.
    ceiling : (3,) float, optional
        Per-channel top of the range: the common factor is limited so that no channel passes
        its top (the ratio is kept rather than one channel clipped).

    Returns
    -------
    (3,) float64

    Examples
    --------
    >>> linked_kappa([1.0, 2.0, 4.0], 0, 2.0).tolist()
    [2.0, 4.0, 8.0]
    >>> linked_kappa([1.0, 2.0, 4.0], 0, 2.0, ceiling=[10, 10, 6]).tolist()
    [1.5, 3.0, 6.0]
    >>> linked_kappa([0.0, 1.0, 1.0], 0, 0.5).tolist()   # from black the channels meet
    [0.5, 0.5, 0.5]
    """
    k = check_kappa(kappa, 3).copy()
    if channel not in (0, 1, 2):
        raise InputError(f"channel must be 0, 1 or 2 (R, G, B), got {channel!r}")
    value = float(check_kappa(value, 1)[0])
    factor_base = k[channel]
    new = k * (value / factor_base) if factor_base > 0 else np.full(3, value)
    if ceiling is not None:
        top = np.asarray(ceiling, np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            over = np.where(new > 0, top / new, np.inf)
        shrink = min(float(np.min(over)), 1.0)
        new = new * shrink
    return new


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
        return f"albedo ({now}); measured ({was})"

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

    def set_channel(self, uid: int, channel: int, value: float, *, linked: bool) -> str:
        """One channel's κ from the slider or the numeric entry; linked channels keep their ratio."""
        kappa = self.doc.target(uid).kappa.copy()
        if linked:
            kappa = linked_kappa(kappa, channel, value, ceiling=self._refusal_ceiling(uid))
        else:
            kappa[channel] = float(check_kappa(value, 1)[0])
        return self.set_kappa(uid, kappa)

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

    def _refusal_ceiling(self, uid: int) -> np.ndarray | None:
        """Per channel, the κ a linked move must not reach (1 / albedo, just below), when absolute albedo is known."""
        albedo = self.colour(uid).albedo
        return None if albedo is None else np.maximum((1.0 - 1e-6) / albedo, KAPPA_MIN)
