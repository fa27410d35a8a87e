"""What is known of one target's colour, and the colour requests it turns into κ.

One object answers every way an artist asks for a colour — a typed or picked colour, an
absolute albedo, the colour of another target, the colour a surface shows in the photograph
— and says which requests physics refuses (an albedo of 1 or more) and which recolors the
captured order cannot follow (:func:`engine.colour.convergence`). The command line and the
app both use it, so they give the same κ for the same request.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from engine.checks import check_float_image, check_kappa
from engine.colour import (
    convergence,
    direct_colour,
    kappa_ceiling,
    kappa_for_albedo,
    kappa_for_colour,
)
from engine.decompose import Decomposition
from engine.errors import InputError

__all__ = ["NO_REFERENCE", "TargetColour"]

#: Why albedo is relative when nothing says otherwise.
NO_REFERENCE = "albedo is relative: no colour checker or reference card measured it"


@dataclass(frozen=True, eq=False)
class TargetColour:
    """A target's colour as far as it was measured.

    Parameters
    ----------
    decomposition : Decomposition or None
        The target's decomposition (None for a target matched against but not recolored).
    direct : (H, W, 3) float, optional
        The target's direct image D (projector light; zero where not measured).
    albedo : (3,) float, optional
        The target's absolute albedo, when a reference measured it (:mod:`engine.albedo`).
    relative : str
        Why ``albedo`` is None (shown to the artist).

    Examples
    --------
    >>> comps = np.zeros((2, 1, 2, 3), np.float32)
    >>> comps[0, 0, 0] = [0.1, 0.4, 0.1]; comps[1, 0, 0] = 0.01
    >>> d = Decomposition(comps, np.zeros((1, 2, 3), np.float32), np.array([[True, False]]))
    >>> wall = TargetColour(d, albedo=[0.1, 0.8, 0.1])
    >>> np.round(wall.for_albedo([0.2, 0.1, 0.8]), 3).tolist()
    [2.0, 0.125, 8.0]
    >>> wall.for_albedo([0.2, 0.1, 1.2])
    Traceback (most recent call last):
    ...
    engine.errors.InputError: an albedo of 1 or more (B = 1.2) is impossible: ...
    """

    decomposition: Decomposition | None
    direct: np.ndarray | None = None
    albedo: np.ndarray | None = None
    relative: str = NO_REFERENCE

    def __post_init__(self) -> None:
        if self.decomposition is not None and not isinstance(self.decomposition, Decomposition):
            raise InputError(f"decomposition must be an engine.decompose.Decomposition, got "
                             f"{type(self.decomposition).__name__}")
        if self.direct is not None:
            d = check_float_image("direct", self.direct, ndim=3)
            if d.shape[2] != 3:
                raise InputError(f"direct must be (H, W, 3), got {d.shape}")
            object.__setattr__(self, "direct", d)
        if self.albedo is not None:
            rho = np.asarray(self.albedo, np.float64)
            if rho.shape != (3,) or not np.all(np.isfinite(rho)) or np.any(rho <= 0):
                raise InputError(f"albedo must be 3 positive numbers (R, G, B), got {rho.tolist()!r:.80}")
            object.__setattr__(self, "albedo", rho)

    # ------------------------------------------------------------------ what it is now

    @cached_property
    def current(self) -> np.ndarray:
        """(3,) linear: the target's colour now — ``R^0 L_d`` white-balanced by D when D is known
        (:func:`engine.colour.direct_colour`): the paint's colour at the target's brightness."""
        return direct_colour(self._needs_decomposition(), direct=self.direct)

    @cached_property
    def seen(self) -> np.ndarray:
        """(3,) linear: ``R^0 L_d`` as the photograph's light shows it (not white-balanced)."""
        return direct_colour(self._needs_decomposition())

    @cached_property
    def direct_mean(self) -> np.ndarray:
        """(3,) mean D over the pixels where it was measured (over the decomposition's target if any)."""
        if self.direct is None:
            raise InputError("the target's direct image D was not measured: it can only be matched by its colour")
        lit = np.all(self.direct > 0, axis=-1)
        if self.decomposition is not None:
            lit &= self.decomposition.target
        if not lit.any():
            raise InputError("the target's direct image D is zero everywhere: it was not lit by the projector")
        return self.direct[lit].astype(np.float64).mean(axis=0)

    def colour(self, kappa) -> np.ndarray:
        """(3,) the target's colour after recoloring with ``kappa`` (Eq. 3 scales ``R^0 L_d`` by κ)."""
        return self.current * check_kappa(kappa, 3)

    def new_albedo(self, kappa) -> np.ndarray | None:
        """(3,) the absolute albedo after recoloring with ``kappa``, or None when albedo is relative."""
        return None if self.albedo is None else self.albedo * check_kappa(kappa, 3)

    def ceiling(self) -> np.ndarray:
        """(3,) top of the κ range per channel: 1 / albedo when known, else the series' divergence
        estimate (:func:`engine.colour.kappa_ceiling`)."""
        return kappa_ceiling(self._needs_decomposition(), self.albedo)

    # ------------------------------------------------------------------ requests → κ

    def for_colour(self, wanted, *, keep_luminance: bool = False) -> np.ndarray:
        """κ that turns the target's colour (:attr:`current`) into ``wanted`` (linear)."""
        return kappa_for_colour(self.current, wanted, keep_luminance=keep_luminance)

    def for_seen(self, picked, *, keep_luminance: bool = False) -> np.ndarray:
        """κ that makes the target's direct light look like ``picked``, a colour seen in the same photograph.

        The picked surface's colour includes the light where it stands (and its own
        interreflections), so it is compared with the target's light as the photograph shows
        it (:attr:`seen`), not white-balanced.
        """
        return kappa_for_colour(self.seen, picked, keep_luminance=keep_luminance)

    def for_albedo(self, wanted) -> np.ndarray:
        """κ that gives the target the absolute albedo ``wanted``; refused when albedo is relative or ``wanted`` ≥ 1."""
        if self.albedo is None:
            raise InputError(f"cannot ask for an absolute albedo: {self.relative}")
        return kappa_for_albedo(self.albedo, wanted)

    def to_match(self, other: TargetColour, *, keep_luminance: bool = False) -> np.ndarray:
        """κ that gives this target the albedo of ``other``, another measured target.

        Both albedos known: their ratio. Else the ratio of their direct images D — the
        paper's Fig. 7 way, exact when the projector lights both alike (the same place,
        facing the same way); chromaticity is right regardless, brightness is off by the
        ratio of the projector's light on them.

        Raises
        ------
        InputError
            Either target's D was not measured (pick the other's colour in the photograph instead).
        """
        if self.albedo is not None and other.albedo is not None:
            kappa = other.albedo / self.albedo
        elif self.direct is not None and other.direct is not None:
            kappa = other.direct_mean / self.direct_mean
        else:
            raise InputError("matching a target needs both targets' direct images D, measured when they are "
                             "acquired; pick the other surface's colour in the photograph instead")
        if keep_luminance:
            kappa = kappa_for_colour(self.current, self.current * kappa, keep_luminance=True)
        return kappa

    # ------------------------------------------------------------------ what physics says

    def check(self, kappa) -> str:
        """Refuse an impossible κ; return a warning (or ``""``) for one the captured order cannot follow.

        Raises
        ------
        InputError
            With the absolute albedo known, a κ that gives an albedo of 1 or more (a surface
            cannot reflect more light than it receives).
        """
        k = check_kappa(kappa, 3)
        if self.albedo is not None:
            new = self.albedo * k
            over = [f"{'RGB'[c]} = {new[c]:.3g}" for c in range(3) if new[c] >= 1]
            if over:
                raise InputError(f"κ {np.round(k, 4).tolist()} would give the target an albedo of 1 or more "
                                 f"({', '.join(over)}): impossible, a surface cannot reflect more light than it "
                                 f"receives; κ must stay below {np.round(1 / self.albedo, 3).tolist()}")
        return convergence(self._needs_decomposition(), k).message()

    def _needs_decomposition(self) -> Decomposition:
        if self.decomposition is None:
            raise InputError("this target was not acquired: its colour is measured from its decomposition")
        return self.decomposition
