"""A one-frame health check of a rig: ``albedit devices --check NAME``.

Opens the rig, reports both devices' resolutions, shows black on the projector, takes one
frame, and reports its exposure, radiance range and the fraction of saturated pixels, then
closes the rig (which leaves the projector black and releases the camera).
"""

from __future__ import annotations

import numpy as np

from devices.registry import open_rig

__all__ = ["check_rig"]


def _size(resolution) -> str:
    if resolution is None:
        return "unknown until the first capture"
    h, w = resolution
    return f"{w}x{h}"


def check_rig(name: str, **options) -> str:
    """Open rig ``name``, take one frame, close it, and describe what happened.

    Parameters
    ----------
    name : str
        A rig name for :func:`devices.open_rig` (``"virtual:cornell"``, ``"gphoto2"``, ...).
    **options
        Passed to the backend's opener.

    Returns
    -------
    str
        Several lines: rig, camera and projector resolutions, the frame's exposure, gain,
        radiance range and saturated fraction, and any backend warnings.

    Raises
    ------
    InputError, DeviceError
        The rig cannot be opened or the frame cannot be taken (the rig is closed first).

    Examples
    --------
    >>> print(check_rig("virtual:cornell", ideal=True).splitlines()[0])
    rig virtual:cornell: opened
    """
    lines = []
    with open_rig(name, **options) as rig:
        lines.append(f"rig {rig.name}: opened")
        cam, proj = rig.camera, rig.projector
        lines.append(f"camera: {type(cam).__name__}, {_size(getattr(cam, 'resolution', None))}")
        lines.append(f"projector: {type(proj).__name__}, {_size(proj.resolution)}, {proj.bit_depth}-bit")
        rig.blank()
        frame = cam.capture()
        image = np.asarray(frame.image)
        saturated = np.asarray(frame.saturated, bool)
        lines.append(f"frame: {image.shape[1]}x{image.shape[0]}, projector black, "
                     f"exposure {frame.exposure:g} s, gain {frame.gain:g}")
        finite = image[np.isfinite(image)]
        low, high = (float(finite.min()), float(finite.max())) if finite.size else (float("nan"), float("nan"))
        median = float(np.median(finite)) if finite.size else float("nan")
        lines.append(f"radiance: min {low:.4g}, median {median:.4g}, max {high:.4g}")
        lines.append(f"saturated: {saturated.mean():.2%} of pixels")
        if image.shape[:2] != tuple(cam.resolution):
            lines.append(f"PROBLEM: the frame is {_size(image.shape[:2])} but the camera says {_size(cam.resolution)}")
        if saturated.mean() > 0.01:
            lines.append("warning: more than 1% of pixels clipped with the projector black; shorten the exposure")
        for warning in getattr(cam, "warnings", []) or []:
            lines.append(f"camera warning: {warning}")
    lines.append("rig closed")
    return "\n".join(lines)
