"""How noisy a measured decomposition is, and the noise-reduction radius it calls for. Qt-free.

Noise reduction (:func:`engine.denoise.denoise_components`) smooths the interaction
components; on noise-free data it only blurs the interreflections (the ideal virtual rig's
Fig. 6 error grows from 0.14 % to 1.2 % at radius 4). So the radius is chosen from the data:
the components' noise is estimated inside the target with Immerkær's Laplacian-difference
operator (second differences cancel smooth interreflections), relative to their level, and
:func:`denoise_radius` skips the filter when that is small and sizes it otherwise.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import binary_erosion, convolve

#: Relative noise below which the components are left alone.
SKIP_BELOW = 0.05
#: Relative noise the filter aims to leave (a radius-r filter averages about (2r + 1)² pixels).
AIM = 0.1
MAX_RADIUS = 8

_OPERATOR = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)


def component_noise(decomposition) -> float:
    """Relative noise of the noisiest interreflection component on the target (NaN when it cannot be measured).

    For each component ``R^i L_d`` with i ≥ 1, the noise σ is Immerkær's estimate
    ``sqrt(π/2) · mean|I * N| / 6`` over target pixels whose 3×3 neighbourhood is all target,
    divided by the component's median level there.

    Parameters
    ----------
    decomposition : engine.decompose.Decomposition

    Returns
    -------
    float
        σ / level of the noisiest component (ideal virtual rig ≈ 0.006; realistic camera with 16
        frames averaged ≈ 0.7 at 4th order); NaN with fewer than 16 target pixels inside its edge
        or no interreflection component (order 1), which it once reported as 0: "no noise".

    References
    ----------
    J. Immerkær, "Fast noise variance estimation", Computer Vision and Image Understanding 64(2), 1996.
    """
    inner = binary_erosion(np.asarray(decomposition.target, bool), np.ones((3, 3), bool))
    if inner.sum() < 16 or decomposition.components.shape[0] < 2:
        return math.nan
    worst = 0.0
    for comp in decomposition.components[1:]:
        c = np.asarray(comp, np.float32).mean(axis=-1)
        level = float(np.median(np.abs(c[inner])))
        if level <= 0:
            continue
        sigma = math.sqrt(math.pi / 2) * float(np.abs(convolve(c, _OPERATOR, mode="nearest"))[inner].mean()) / 6
        worst = max(worst, sigma / level)
    return worst


def denoise_radius(decomposition) -> tuple[int, float]:
    """The noise-reduction radius for ``decomposition`` (0: leave it as measured) and its noise (NaN: unknown).

    Examples
    --------
    >>> from engine.decompose import Decomposition
    >>> t = np.zeros((32, 32), bool); t[4:28, 4:28] = True
    >>> smooth = np.broadcast_to(np.linspace(1.0, 2.0, 32, dtype=np.float32)[None, :, None], (32, 32, 3))
    >>> inside = np.stack([smooth * 0.5**i for i in range(3)])
    >>> d = Decomposition.from_components(inside, inside[:2] * 0, smooth, t)
    >>> denoise_radius(d)[0]
    0
    >>> noisy = inside + np.random.default_rng(0).normal(0, 0.1, inside.shape).astype(np.float32)
    >>> denoise_radius(Decomposition.from_components(noisy, inside[:2] * 0, smooth, t))[0] > 0
    True
    >>> radius, noise = denoise_radius(Decomposition.from_components(inside[:1], inside[:0], smooth, t))  # order 1
    >>> radius, bool(np.isnan(noise))
    (0, True)
    """
    noise = component_noise(decomposition)
    if math.isnan(noise) or noise < SKIP_BELOW:  # unknown noise: leave the decomposition as measured
        return 0, noise
    return int(min(max(math.ceil((noise / AIM - 1) / 2), 1), MAX_RADIUS)), noise
