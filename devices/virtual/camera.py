"""The virtual camera: a linear RAW sensor with shot noise, read noise, ADC and clipping."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from devices.base import Frame
from engine.errors import InputError

# Photon counts are drawn from a Poisson law below this many electrons, from its Gaussian
# limit N(l, l) above (indistinguishable there, and several times faster).
GAUSSIAN_ABOVE = 1000.0


@dataclass(frozen=True)
class CameraModel:
    """Sensor parameters (the ground truth of the camera's noise and scale).

    Attributes
    ----------
    electrons_per_radiance : float
        Photo-electrons per unit scene radiance per second of exposure.
    electrons_per_dn : float
        Electrons per raw count at gain 1 (gain g divides it by g).
    black_level : float
        Raw offset added to every pixel (DN).
    read_noise : float
        Gaussian read noise, electrons rms.
    bits : int
        ADC bit depth; raw values are integers in ``[0, 2**bits - 1]``.
    full_well : float
        Electrons at which a pixel saturates.
    ideal : bool
        No noise, no quantisation, no black level; saturation far beyond any use.

    Notes
    -----
    ``raw = clip(round(min(Poisson(radiance * k * t) + N(0, read^2), full_well) * g / e_dn
    + black), 0, white)`` and ``image = (raw - black) / (t * g * calibration)`` with
    ``calibration = k / e_dn``, so the mean image equals the radiance at any exposure ``t``
    and gain ``g`` (below saturation).

    Examples
    --------
    >>> perfect = CameraModel.perfect()
    >>> raw = perfect.expose(np.ones((1, 1, 3)), 0.1, 1.0, None)[0]
    >>> perfect.develop(raw, 0.1, 1.0)[0, 0].tolist()
    [1.0, 1.0, 1.0]
    """

    electrons_per_radiance: float = 4.0e5
    electrons_per_dn: float = 1.25
    black_level: float = 512.0
    read_noise: float = 3.0
    bits: int = 14
    full_well: float = 20000.0
    ideal: bool = False

    @classmethod
    def realistic(cls) -> CameraModel:
        """A 14-bit RAW camera: 20 000 e- full well, 3 e- read noise, black level 512."""
        return cls()

    @classmethod
    def perfect(cls) -> CameraModel:
        """The ideal camera: returns the radiance exactly, clipping only at 1e12 electrons."""
        return cls(black_level=0.0, read_noise=0.0, bits=64, full_well=1e12, ideal=True)

    def full_scale(self, exposure: float, gain: float) -> float:
        """Radiance at which a pixel clips at ``exposure`` and ``gain`` (``inf`` for the ideal camera,
        whose 1e12-electron well no scene reaches: it returns radiance at any exposure).

        Examples
        --------
        >>> m = CameraModel.realistic()
        >>> round(m.full_scale(0.01, 1.0), 4)  # the ADC's white level comes before the full well here
        4.9597
        """
        if self.ideal:
            return float("inf")
        well = self.full_well
        adc = (self.white_level - self.black_level) * self.electrons_per_dn / gain
        return min(well, adc) / (self.electrons_per_radiance * exposure)

    @property
    def calibration(self) -> float:
        """Raw counts per unit radiance per second at gain 1."""
        return self.electrons_per_radiance / self.electrons_per_dn

    @property
    def white_level(self) -> float:
        """Largest raw value (DN)."""
        return float(2**self.bits - 1)

    def expose(self, radiance: np.ndarray, exposure: float, gain: float, rng: np.random.Generator | None):
        """Raw counts and saturation mask of one exposure.

        Parameters
        ----------
        radiance : (H, W, 3) float
            Noise-free scene radiance.
        exposure : float
            Seconds.
        gain : float
            Linear gain.
        rng : numpy.random.Generator or None
            Noise source (unused when ideal).

        Returns
        -------
        raw : (H, W, 3) float32
            Raw values (integers in DN unless ideal).
        saturated : (H, W) bool
            Any channel clipped (full well or ADC white level).
        """
        electrons = np.asarray(radiance, np.float32) * np.float32(self.electrons_per_radiance * exposure)
        if self.ideal:
            clipped = electrons >= self.full_well
            raw = np.minimum(electrons, np.float32(self.full_well))
            raw *= np.float32(gain / self.electrons_per_dn)
            return raw, _any_channel(clipped)
        if rng is None:
            raise ValueError("a noisy camera model needs an rng (only an ideal model exposes without one)")
        # photon noise: Poisson; above GAUSSIAN_ABOVE electrons its Gaussian limit N(l, l)
        # (skewness < 3 %), drawn together with the read noise
        noise = rng.standard_normal(electrons.shape, dtype=np.float32)
        signal = electrons + np.float32(self.read_noise**2)
        np.sqrt(signal, out=signal)
        signal *= noise
        signal += electrons
        small = np.flatnonzero(electrons.ravel() < GAUSSIAN_ABOVE)
        if small.size:
            flat = signal.reshape(-1)
            lam = electrons.ravel()[small].astype(np.float64)
            flat[small] = rng.poisson(lam).astype(np.float32) + np.float32(self.read_noise) * noise.ravel()[small]
        clipped = signal >= self.full_well
        np.minimum(signal, np.float32(self.full_well), out=signal)
        signal *= np.float32(gain / self.electrons_per_dn)
        signal += np.float32(self.black_level)
        raw = np.rint(signal, out=signal)
        white = np.float32(self.white_level)
        clipped |= raw >= white
        np.clip(raw, 0, white, out=raw)
        return raw, _any_channel(clipped)

    def noise(self, exposure: float, gain: float) -> dict:
        """The variance of a developed frame, ``shot · I + read`` (radiance units), and its clip level.

        Photon noise ``I / (k t)``, read noise ``r² / (k t)²`` and ADC rounding
        ``1 / (12 (t g calibration)²)``, with ``k`` the electrons per unit radiance per second;
        ``clip`` is the radiance at which the frame saturates. Zero noise when ideal. This is
        what :meth:`engine.noise.CameraNoise.from_metadata` reads from every frame.
        """
        electrons = self.electrons_per_radiance * exposure
        scale = exposure * gain * self.calibration
        clip = min(self.full_well / electrons, (self.white_level - self.black_level) / scale)
        if self.ideal:
            return {"shot": [0.0] * 3, "read": [0.0] * 3, "clip": clip}
        read = self.read_noise**2 / electrons**2 + 1.0 / (12.0 * scale * scale)
        return {"shot": [1.0 / electrons] * 3, "read": [read] * 3, "clip": clip}

    def develop(self, raw: np.ndarray, exposure: float, gain: float) -> np.ndarray:
        """Linear radiance from raw values: ``(raw - black) / (exposure * gain * calibration)``."""
        return ((raw - self.black_level) / (exposure * gain * self.calibration)).astype(np.float32)


def _any_channel(mask: np.ndarray) -> np.ndarray:
    """``mask.any(axis=-1)`` for 3 channels, without numpy's slow short-axis reduction."""
    return mask[..., 0] | mask[..., 1] | mask[..., 2]


class VirtualCamera:
    """The camera of a virtual rig (implements :class:`devices.base.Camera`).

    It photographs the scene lit by the ambient light (if the rig's switch is on) and by
    whatever the rig's projector currently emits.

    Parameters
    ----------
    renderer : devices.virtual.render.Renderer
    projector : devices.virtual.projector.VirtualProjector
    model : CameraModel
    rng : numpy.random.Generator
        The camera's own noise source.
    name : str
        Rig name, recorded in frame metadata.

    Attributes
    ----------
    resolution : (H, W)
    exposure : float
        Seconds, > 0 (validated when set).
    gain : float
        Linear gain, >= 1 (validated when set).
    model : CameraModel
    rng : numpy.random.Generator
        Noise of frames without an identity (live view); its seed also seeds identified frames.
    captures : int
        Number of frames taken.
    frame_identity : str or None
        Set by :class:`engine.acquire.Recorder` before a frame (capture name, pattern, frame
        index): that frame's noise is seeded from the rig's seed and it, never from the
        process (:attr:`engine.rig.Camera.frame_identity`).
    """

    def __init__(self, renderer, projector, model: CameraModel, rng: np.random.Generator, name: str):
        self._renderer = renderer
        self._projector = projector
        self.model = model
        self.rng = rng
        self.name = name
        self.resolution = renderer.shape
        self._exposure = 1.0 / 30.0
        self._gain = 1.0
        self.captures = 0
        self.frame_identity: str | None = None

    @property
    def exposure(self) -> float:
        """Exposure time in seconds."""
        return self._exposure

    @exposure.setter
    def exposure(self, value: float) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                or not np.isfinite(value) or not 0 < value <= 3600:
            raise InputError(f"exposure must be a number of seconds in (0, 3600], got {value!r}")
        self._exposure = float(value)

    @property
    def gain(self) -> float:
        """Linear sensor gain (ISO / base ISO)."""
        return self._gain

    @gain.setter
    def gain(self, value: float) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                or not np.isfinite(value) or not 1 <= value <= 1024:
            raise InputError(f"gain must be a number in [1, 1024], got {value!r}")
        self._gain = float(value)

    def capture(self) -> Frame:
        """Take one frame of the scene as lit now.

        Returns
        -------
        Frame
            ``image`` linear radiance (black removed, divided by exposure, gain and the
            calibration constant), ``saturated`` clipped pixels, metadata.
        """
        radiance = self._renderer.render(self._projector.emitted)
        raw, saturated = self.model.expose(radiance, self._exposure, self._gain, self._frame_rng())
        if self.model.ideal:
            image = np.asarray(radiance, np.float32)
            if saturated.any():
                image = np.where(saturated[..., None], self.model.develop(raw, self._exposure, self._gain), image)
        else:
            image = self.model.develop(raw, self._exposure, self._gain)
        self.captures += 1
        meta = {"device": self.name, "ideal": self.model.ideal, "ambient": bool(self._renderer.ambient),
                "capture": self.captures, "calibration": self.model.calibration,
                "white_level": self.model.white_level, "read_noise_e": self.model.read_noise,
                "electrons_per_dn": self.model.electrons_per_dn,
                "noise": self.model.noise(self._exposure, self._gain)}
        return Frame(image=image, exposure=self._exposure, gain=self._gain,
                     black_level=self.model.black_level, saturated=saturated, metadata=meta,
                     full_scale=self.model.full_scale(self._exposure, self._gain))

    def _frame_rng(self) -> np.random.Generator:
        """The noise of this frame: from the rig's seed and :attr:`frame_identity` when the recorder set one.

        The identity is used once; frames without one (a live view) draw from :attr:`rng`.
        """
        identity, self.frame_identity = self.frame_identity, None
        if identity is None:
            return self.rng
        words = np.frombuffer(hashlib.sha256(identity.encode()).digest(), np.uint32)
        seed = self.rng.bit_generator.seed_seq
        # default_rng(seed) and every Generator of the rig factories carry a SeedSequence
        assert isinstance(seed, np.random.SeedSequence), "the rig's rng must come from a seed"
        return np.random.default_rng(np.random.SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key, *words)))

    def __repr__(self) -> str:
        return f"VirtualCamera({self.resolution}, ideal={self.model.ideal})"
