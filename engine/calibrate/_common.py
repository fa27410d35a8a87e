"""Small helpers shared by the calibration modules (private); input checks live in :mod:`engine.checks`."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np


def wh(resolution: tuple[int, int]) -> str:
    """Format an ``(H, W)`` resolution the way people say it: ``"W×H"``."""
    return f"{resolution[1]}×{resolution[0]}"


class Patterns(Sequence):
    """A read-only, lazily rendered sequence of projector images.

    Each item is a new float32 ``(Hp, Wp, 3)`` array in [0, 1], made when it is asked for, so a
    long sequence (42 Gray-code frames of a 1920×1080 projector would be 1.1 GB as float32)
    costs only its recipe. ``names[i]`` says what image ``i`` is, for capture logs.
    """

    def __init__(self, render: Callable[[int], np.ndarray], names: Sequence[str], resolution: tuple[int, int]):
        self._render = render
        self.names = tuple(names)
        self.resolution = resolution

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        i = int(index)
        if i < 0:
            i += len(self)
        if not 0 <= i < len(self):
            raise IndexError(f"pattern index {index} out of range for {len(self)} patterns")
        return self._render(i)

    def __repr__(self) -> str:
        return f"Patterns({len(self)} images of {wh(self.resolution)}: {', '.join(self.names[:3])}, ...)"


def plane_to_rgb(plane: np.ndarray) -> np.ndarray:
    """Return a contiguous float32 ``(H, W, 3)`` copy of a single-channel plane."""
    out = np.empty(plane.shape + (3,), np.float32)
    out[...] = plane[..., None]
    return out
