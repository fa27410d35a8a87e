"""Predicting re-emission captures instead of taking them (paper Sec. 5).

Light transport is linear: if the light to emit on a target is (nearly) a combination of
lights already emitted there, ``L ≈ Σ w_i L_i`` (Eq. 10), its capture is the same
combination of their captures, ``I ≈ Σ w_i I_i`` (Eq. 11). A :class:`Predictor` keeps every
(light, capture) pair emitted on one target — across all the sequences of a cascade, which is
what makes predictions frequent there — and fits the weights per channel (each channel is
emitted and transported on its own).

Predictions are made at every level of a cascade: at level 0 of a raw capture, at level ℓ ≥ 1
of a *recolored* observation (the scene's response with targets < ℓ recolored, Sec. 5's
recolored prediction), which replaces the K^ℓ captures of its decomposition.

Two policies decide when a prediction replaces a capture:

``linear`` (the paper's): within a sequence, capture ``I_r`` and compare it with its
prediction; once the relative error is below the threshold, predict the rest of the sequence.

``span`` (ours): predict whenever the prediction's error is *bounded* below the threshold
before capturing: with ``e = L − Σ w_i L_i``, ``‖T e‖ / ‖T L‖ ≤ (g_max / g_min) ‖e‖ / ‖L‖``
where ``g = ‖I_i‖ / ‖L_i‖`` are the gains seen so far. No validation capture is spent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from engine.acquire.noise import Noise


class Policy(StrEnum):
    """When predictions replace captures: ``brute`` never, ``linear`` (paper), ``span`` (ours)."""

    BRUTE = "brute"
    LINEAR = "linear"
    SPAN = "span"


@dataclass(frozen=True)
class Adaptive:
    """Adaptive-capture settings.

    Attributes
    ----------
    policy : {"brute", "linear", "span"}
    threshold : float
        Relative error accepted for a predicted observation (paper: 1 %).
    noise_band : bool
        Also accept a prediction whose error is within the noise its capture would carry
        (the relative noise of the last response on that target): such a prediction is as
        good as the capture. Needs the camera's noise (else the threshold alone decides).
    """

    policy: str = Policy.SPAN
    threshold: float = 0.01
    noise_band: bool = True

    def to_dict(self) -> dict:
        return {"policy": str(self.policy), "threshold": self.threshold, "noise_band": self.noise_band}


@dataclass(frozen=True)
class Prediction:
    """A predicted capture.

    Attributes
    ----------
    image : (H, W, 3) float32
        ``Σ w_i I_i`` per channel (Eq. 11).
    light_error : (3,) float
        ``‖L − Σ w_i L_i‖ / ‖L‖`` per channel (Eq. 10's residual).
    bound : float
        Upper bound of the predicted image's relative error (largest over channels).
    weights : (m, 3) float
        ``w_i`` per channel, one row per recorded pair.
    noise : Noise or None
        The prediction's noise, ``Σ w_i`` times the recorded captures' noise (None when
        one of them is unknown).
    """

    image: np.ndarray
    light_error: np.ndarray
    bound: float
    weights: np.ndarray | None = None
    noise: Noise | None = None


@dataclass
class Predictor:
    """The (light, capture) pairs emitted on one target, and predictions from them.

    Parameters
    ----------
    mask : (H, W) bool
        The target: lights are compared on its pixels only.
    """

    mask: np.ndarray
    lights: list = field(default_factory=list)  # each (n, 3) float64: light on the target pixels
    images: list = field(default_factory=list)  # each (H, W, 3) float32: base-removed capture
    noises: list = field(default_factory=list)  # each Noise or None

    def add(self, light: np.ndarray, image: np.ndarray, noise: Noise | None = None) -> None:
        """Record an emitted light (camera space, (H, W, 3)) and the capture it caused (and its noise)."""
        self.lights.append(np.asarray(light, np.float64)[self.mask])
        self.images.append(np.asarray(image, np.float32))
        self.noises.append(noise)

    def predict(self, light: np.ndarray) -> Prediction | None:
        """Predict the capture of ``light`` from the pairs so far (None without any).

        Notes
        -----
        Weights per channel by least squares on the target's pixels (Eq. 10), the image as
        the same combination of the captures (Eq. 11).
        """
        if not self.lights:
            return None
        want = np.asarray(light, np.float64)[self.mask]
        basis = np.stack(self.lights, axis=-1)  # (n, 3, m)
        stack = np.stack(self.images, axis=-1)  # (H, W, 3, m)
        image = np.zeros(self.images[0].shape, np.float64)
        err = np.zeros(3)
        bound = 0.0
        weights = np.zeros((len(self.images), 3))
        for c in range(3):
            a, y = basis[:, c, :], want[:, c]
            norm = np.linalg.norm(y)
            if norm == 0:
                continue
            w, *_ = np.linalg.lstsq(a, y, rcond=None)
            weights[:, c] = w
            err[c] = np.linalg.norm(a @ w - y) / norm
            image[..., c] = stack[..., c, :] @ w
            light_norms = np.linalg.norm(a, axis=0)
            ok = light_norms > 0
            if not ok.any():
                err[c] = 1.0
                bound = np.inf
                continue
            gains = np.linalg.norm(stack[..., c, :].reshape(-1, stack.shape[-1]), axis=0)[ok] / light_norms[ok]
            spread = gains.max() / max(gains.min(), 1e-30)
            bound = max(bound, err[c] * spread)
        noise = None
        if all(n is not None for n in self.noises):
            noise = Noise()
            for w, n in zip(weights, self.noises, strict=True):
                noise = noise + n * w.astype(np.float32)
        return Prediction(image.astype(np.float32), err, float(bound), weights, noise)


def relative_error(image: np.ndarray, reference: np.ndarray, keep: np.ndarray | None = None) -> float:
    """``‖image − reference‖₂ / ‖reference‖₂`` over all channels of the pixels in ``keep``.

    The accuracy measure of every figure (DESIGN.md); ``keep`` (H, W) bool, default all
    pixels, e.g. ``~rig.truth.emitters()`` to leave out a lamp that dominates the norm.
    0 when the reference is zero.
    """
    a = np.asarray(image, np.float64)
    b = np.asarray(reference, np.float64)
    if keep is not None:
        a, b = a[keep], b[keep]
    den = float(np.linalg.norm(b))
    return float(np.linalg.norm(a - b) / den) if den > 0 else 0.0
