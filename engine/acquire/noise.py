"""How the noise of every capture reaches every observation (paper Sec. 6, Discussion).

An observation is a linear function of captures: base light removed, scaling undone,
differences re-emitted and added back (Eq. 12-14), earlier targets recolored (Sec. 4). And
re-emission carries noise forward: the light emitted on the target is made of earlier
captures, so their noise is shown again, reflected straight back by the target (direct
reflection returns exactly the wanted radiance, Sec. 3.3), while the interreflections spread
it over the scene, where it averages out (they are low-pass). The pattern's rounding to the
projector's levels and the error of D (the same in every re-emission) add their own.

:class:`Noise` keeps an image's noise as a sum of independent per-pixel sources,
``Σ_s a_s(x) ξ_s(x)`` with ``ξ_s`` of unit variance, so that covariances between
observations that share a source (the photograph, which is also the base light of every
re-emission; D) come out right. What is approximated: noise re-emitted on the target comes
back exactly (its interreflected part is neglected) and none of it reaches other pixels.
"""

from __future__ import annotations

import itertools

import numpy as np

from engine.noise import packed_index

_FRESH = itertools.count()


class Noise:
    """The noise of one image: independent sources with per-pixel signed standard deviations.

    Parameters
    ----------
    terms : dict[str, (H, W, C) float32], optional
        Source name → coefficient ``a_s``: the image's noise is ``Σ_s a_s ξ_s`` with ``ξ_s``
        independent, unit variance, independent between pixels.

    Examples
    --------
    >>> a = Noise.source("photo", np.full((1, 1, 1), 2.0, np.float32))
    >>> b = Noise.source("capture", np.full((1, 1, 1), 1.0, np.float32))
    >>> d = b - a                       # a capture with the photograph removed
    >>> float(d.variance()[0, 0, 0]), float(Noise.covariance(d, a)[0, 0, 0])
    (5.0, -4.0)
    """

    __slots__ = ("terms",)

    def __init__(self, terms: dict | None = None):
        self.terms: dict[str, np.ndarray] = dict(terms or {})

    @classmethod
    def source(cls, name: str, std) -> Noise:
        """One independent source of standard deviation ``std`` (per pixel and channel)."""
        return cls({name: np.asarray(std, np.float32)})

    @classmethod
    def fresh(cls, std, prefix: str = "merged") -> Noise:
        """A new source, independent of every other (a unique name is made up)."""
        return cls.source(f"{prefix}#{next(_FRESH)}", std)

    def __bool__(self) -> bool:
        return bool(self.terms)

    def _combine(self, other: Noise, sign: float) -> Noise:
        out = dict(self.terms)
        for k, v in other.terms.items():
            out[k] = out[k] + np.float32(sign) * v if k in out else np.float32(sign) * v
        return Noise(out)

    def __add__(self, other: Noise) -> Noise:
        return self._combine(other, 1.0)

    def __sub__(self, other: Noise) -> Noise:
        return self._combine(other, -1.0)

    def __mul__(self, factor) -> Noise:
        f = np.asarray(factor, np.float32)
        return Noise({k: v * f for k, v in self.terms.items()})

    __rmul__ = __mul__

    def variance(self) -> np.ndarray | None:
        """``Σ_s a_s²`` per pixel and channel (None without sources)."""
        out = None
        for v in self.terms.values():
            out = np.square(v) if out is None else out + np.square(v)
        return out

    @staticmethod
    def covariance(a: Noise, b: Noise) -> np.ndarray | None:
        """``Σ_s a_s b_s`` over the sources the two share (None if they share none)."""
        out = None
        for k in a.terms:  # in a's order, not a set's: the same sum bit for bit in every run
            if k not in b.terms:
                continue
            term = a.terms[k] * b.terms[k]
            out = term if out is None else out + term
        return out

    def merged(self, keep=(), prefix: str = "merged") -> Noise:
        """The same variance with every source not in ``keep`` merged into one fresh source.

        Sources other images also hold (the photograph, D) must be kept for their
        covariances to stay right; private ones can be merged to keep the term count small.
        """
        kept = {k: v for k, v in self.terms.items() if k in keep}
        rest = [v for k, v in self.terms.items() if k not in keep]
        if not rest:
            return Noise(kept)
        var = np.square(rest[0])
        for v in rest[1:]:
            var = var + np.square(v)
        return Noise(kept) + Noise.fresh(np.sqrt(var), prefix)


def covariance_stack(noises: list[Noise], shape) -> np.ndarray:
    """Packed covariance of images' noises: ``(K(K+1)/2, H, W, C)`` float32, upper triangle row-major.

    Entry :func:`engine.noise.packed_index` ``(i, j, K)`` holds ``Cov(n_i, n_j)``.
    """
    k = len(noises)
    out = np.zeros((k * (k + 1) // 2,) + tuple(shape), np.float32)
    for i in range(k):
        for j in range(i, k):
            c = noises[i].variance() if i == j else Noise.covariance(noises[i], noises[j])
            if c is not None:
                out[packed_index(i, j, k)] = c
    return out
