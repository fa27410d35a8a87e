"""The virtual projector: input image -> 8-bit levels -> response -> black level -> crosstalk.

The rig renders from whatever the projector currently emits, as a real scene would.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.checks import check_float_image
from engine.errors import InputError


@dataclass(frozen=True, eq=False)
class ProjectorModel:
    """How projector input becomes emitted light (the ground truth calibration must find).

    Attributes
    ----------
    gamma : (3,) float64
        Response exponent per primary: level ``q`` emits ``q ** gamma``.
    black_level : float
        Fraction of full output emitted when showing 0 (light leak of a DLP/LCD).
    crosstalk : (3, 3) float64
        ``emitted[c] = sum_k crosstalk[c, k] * primary[k]``: row = emitted (camera) channel,
        column = projector primary.
    bit_depth : int
        Input levels are quantised to ``2**bit_depth - 1`` steps (unless ``ideal``).
    ideal : bool
        True: no quantisation, linear response, no black level, identity crosstalk.

    Examples
    --------
    >>> m = ProjectorModel.realistic()
    >>> float(m.emit(np.zeros((1, 1, 3), np.float32))[0, 0, 1]) > 0  # black level leaks
    True
    >>> ProjectorModel.perfect().emit(np.full((1, 1, 3), 0.5, np.float32))[0, 0].tolist()
    [0.5, 0.5, 0.5]
    """

    gamma: np.ndarray = field(default_factory=lambda: np.array([2.2, 2.25, 2.15]))
    black_level: float = 0.003
    crosstalk: np.ndarray = field(default_factory=lambda: np.array(
        [[1.0, 0.05, 0.01], [0.04, 1.0, 0.06], [0.01, 0.03, 1.0]]))
    bit_depth: int = 8
    ideal: bool = False

    @classmethod
    def realistic(cls) -> ProjectorModel:
        """A DLP-like projector: gamma about 2.2, 0.3 % black level, a few % crosstalk."""
        return cls()

    @classmethod
    def perfect(cls) -> ProjectorModel:
        """The ideal projector: emitted = input, exactly."""
        return cls(gamma=np.ones(3), black_level=0.0, crosstalk=np.eye(3), ideal=True)

    def primaries(self, image: np.ndarray) -> np.ndarray:
        """Linear output of each primary (quantised, response, black level), before crosstalk.

        Parameters
        ----------
        image : (..., 3) float in [0, 1]

        Returns
        -------
        (..., 3) float32
        """
        image = np.asarray(image, np.float32)
        if self.ideal:
            return image.copy()
        top = 2**self.bit_depth - 1
        levels = np.rint(image * top).astype(np.intp)
        lut = (self.black_level + (1 - self.black_level)
               * (np.arange(top + 1)[:, None] / top) ** self.gamma[None, :]).astype(np.float32)
        return np.stack([lut[levels[..., k], k] for k in range(3)], axis=-1)

    def emit(self, image: np.ndarray) -> np.ndarray:
        """Linear light emitted per channel, relative to the ideal full white.

        Parameters
        ----------
        image : (..., 3) float in [0, 1]
            Projector input.

        Returns
        -------
        (..., 3) float32
        """
        p = self.primaries(image)
        if self.ideal:
            return p
        x = self.crosstalk.astype(np.float32)
        return np.stack([x[c, 0] * p[..., 0] + x[c, 1] * p[..., 1] + x[c, 2] * p[..., 2]
                         for c in range(3)], axis=-1)


def check_pattern(image, resolution: tuple[int, int], *, name: str = "image") -> np.ndarray:
    """Validate a projector input image and return it as float32.

    Raises
    ------
    InputError
        Not a float array, wrong shape, non-finite values, or values outside [0, 1].
    """
    image = check_float_image(name, image, ndim=3)
    hp, wp = resolution
    if image.shape != (hp, wp, 3):
        raise InputError(f"{name} must have shape {(hp, wp, 3)} (projector pixels x RGB), got {image.shape}")
    lo, hi = float(image.min()), float(image.max())
    if lo < 0 or hi > 1:
        raise InputError(f"{name} values must be in [0, 1] (projector input), got min {lo:g}, max {hi:g}; "
                         "scale the pattern and undo the scale after capture")
    return image.astype(np.float32)


class VirtualProjector:
    """The projector of a virtual rig (implements :class:`devices.base.Projector`).

    Parameters
    ----------
    model : ProjectorModel
    resolution : (Hp, Wp)

    Attributes
    ----------
    resolution : (Hp, Wp)
    bit_depth : int
        The model's input bits (8); 24 for an ideal projector, whose float32 input is used
        unquantised (24 bits is float32's resolution near full light).
    model : ProjectorModel
    shown : int
        Number of frames shown so far.
    """

    def __init__(self, model: ProjectorModel, resolution: tuple[int, int]):
        self.model = model
        self.resolution = (int(resolution[0]), int(resolution[1]))
        self.bit_depth = 24 if model.ideal else model.bit_depth
        self.shown = 0
        self._input = np.zeros(self.resolution + (3,), np.float32)
        self._emitted = model.emit(self._input)
        self._emitted.setflags(write=False)

    def show(self, image: np.ndarray) -> None:
        """Display ``image`` (float ``(Hp, Wp, 3)`` in [0, 1]); returns once it is "on the wall".

        Raises
        ------
        InputError
            Wrong shape or dtype, non-finite values, or values outside [0, 1].
        """
        image = check_pattern(image, self.resolution)
        self._input = image.copy()
        emitted = self.model.emit(image)
        emitted.setflags(write=False)
        self._emitted = emitted
        self.shown += 1

    @property
    def emitted(self) -> np.ndarray:
        """(Hp, Wp, 3) float32 linear light now emitted (read-only)."""
        return self._emitted

    @property
    def image(self) -> np.ndarray:
        """(Hp, Wp, 3) float32 copy of the input now shown."""
        return self._input.copy()

    def __repr__(self) -> str:
        return f"VirtualProjector({self.resolution}, ideal={self.model.ideal})"
