"""Noise-free radiance of the virtual scene for a given ambient state and projector output."""

from __future__ import annotations

import cv2
import numpy as np

from devices.virtual.scene import Scene
from devices.virtual.setup import Setup
from devices.virtual.transport import Resolvent


class Renderer:
    """Turns "ambient light on/off" and the projector's emitted light into camera radiance.

    Parameters
    ----------
    scene : Scene
    setup : Setup
    defocus : float
        Projector blur: the emitted image is blurred by a Gaussian of this standard deviation
        (projector pixels) before it reaches the surfaces (0: in focus).

    Attributes
    ----------
    rho : (Ns, 3) float64
        Albedo of every sample (0 for pixels that see no surface).
    base : Resolvent
        The scene's transport, factored once.
    ambient_light : (Ns, 3) float64
        Direct light (irradiance / pi) from the ambient (emitting) quads.
    emission : (H*W, 3) float64
        Radiance emitted towards the camera at pixels that see a light (mixed pixels: the
        mean over their sub-samples).
    ambient : bool
        Whether the ambient light is on (the rig's switch; captures read it).
    """

    def __init__(self, scene: Scene, setup: Setup, *, defocus: float = 0.0):
        self.scene = scene
        self.setup = setup
        self.defocus = float(defocus)
        h, w = (int(x) for x in setup.resolution)
        self.shape = (h, w)
        self.rho = scene.albedo_at(setup.quad, setup.a, setup.b)
        self.base = Resolvent(setup, self.rho)
        self.ambient_light = setup.light_ff @ scene.emission[setup.light_quads] if len(setup.light_quads) \
            else np.zeros((len(setup.quad), 3))
        vq = setup.quad[:setup.n_visible]
        seen = np.where((vq >= 0)[:, None], scene.emission[np.maximum(vq, 0)], 0.0)
        pq = setup.pixel_quad  # a mixed pixel's centre sample is inert: take what it sees
        seen[:self.n_pixels] = np.where((pq >= 0)[:, None], scene.emission[np.maximum(pq, 0)], 0.0)
        self.emission = setup.pixel_values(seen)
        self.ambient = True
        # every sample gathers from one projector pixel (pixel 0 with gain 0 where unlit)
        self._proj_index = np.where(setup.proj_lit, setup.proj_index, 0).astype(np.intp)
        self._proj_gain = np.where(setup.proj_lit, setup.proj_factor, 0.0)[:, None] * scene.projector_power[None, :]
        self._cache32 = (self.ambient_light.astype(np.float32), self._proj_gain.astype(np.float32),
                         self.emission.astype(np.float32))

    @property
    def n_pixels(self) -> int:
        """``H * W``."""
        return self.shape[0] * self.shape[1]

    def direct_light(self, emitted: np.ndarray | None, *, ambient: bool, dtype=np.float32) -> np.ndarray:
        """Direct light ``E`` (irradiance / pi) at every sample.

        Parameters
        ----------
        emitted : (Hp, Wp, 3) float or None
            Linear light the projector emits (relative to full white), None for none.
        ambient : bool
            Include the ambient light.
        dtype : float32 or float64

        Returns
        -------
        (Ns, 3) ``dtype``
        """
        f32 = np.dtype(dtype) == np.float32
        amb, gain = (self._cache32[0], self._cache32[1]) if f32 else (self.ambient_light, self._proj_gain)
        if emitted is None:
            return amb.copy() if ambient else np.zeros(amb.shape, amb.dtype)
        emitted = np.asarray(emitted)
        if self.defocus > 0:
            emitted = cv2.GaussianBlur(emitted.astype(np.float32), (0, 0), self.defocus, borderType=cv2.BORDER_CONSTANT)
        flat = emitted.reshape(-1, 3)
        e = np.take(flat, self._proj_index, axis=0).astype(amb.dtype, copy=False)
        e *= gain
        if ambient:
            e += amb
        return e

    def to_image(self, radiance: np.ndarray, *, ambient: bool) -> np.ndarray:
        """Camera image ``(H, W, 3)`` from sample radiance (adds the lights seen if on); a mixed
        pixel is the mean of its sub-samples."""
        img = self.setup.pixel_values(radiance)
        if ambient:
            em = self._cache32[2] if radiance.dtype == np.float32 else self.emission
            img = img + em
        return img.reshape(self.shape + (3,))

    def render(self, emitted: np.ndarray | None, *, ambient: bool | None = None, dtype=np.float32) -> np.ndarray:
        """Noise-free radiance seen by the camera.

        Parameters
        ----------
        emitted : (Hp, Wp, 3) or None
            Projector output (see :meth:`direct_light`).
        ambient : bool, optional
            Defaults to the rig's current :attr:`ambient` state.
        dtype : float32 or float64

        Returns
        -------
        (H, W, 3) ``dtype``
        """
        ambient = self.ambient if ambient is None else ambient
        e = self.direct_light(emitted, ambient=ambient, dtype=dtype)
        return self.to_image(self.base.solve(e), ambient=ambient)
