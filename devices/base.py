"""The device protocols every backend implements, and the :class:`Rig` that pairs them.

The protocols (:class:`Frame`, :class:`Camera`, :class:`Projector`) live where they are
consumed, in :mod:`engine.rig`, and are re-exported here for the backends. Nothing outside
``devices/`` knows a vendor API: acquisition and calibration talk only to these protocols.
"""

from __future__ import annotations

import numpy as np

from engine.rig import Camera, Frame, Projector

__all__ = ["Camera", "Frame", "Projector", "Rig"]


class Rig:
    """One camera and one projector, used as a context manager that leaves hardware safe.

    Parameters
    ----------
    name : str
        The name it was opened by, e.g. ``"virtual:cornell"``; recorded in sessions.
    camera, projector
        The two devices.
    targets : dict[str, (H, W) bool], optional
        Named target masks the rig knows (the virtual rig's scene targets).
    truth : object, optional
        Ground truth (virtual rig only).
    identity : str, optional
        The physical rig this one stands for, which calibrations are checked against
        (default: ``name``; a ``replay:`` rig stands for the rig it recorded).
    fingerprint : dict, optional
        What else a calibration of this rig depends on (the virtual rig: scene content, pose,
        ideal), merged into :attr:`fingerprint`.
    """

    def __init__(self, name: str, camera: Camera, projector: Projector, *, targets=None, truth=None, identity=None,
                 fingerprint: dict | None = None):
        self.name = name
        self.identity = identity or name
        self._fingerprint = dict(fingerprint or {})
        self.camera = camera
        self.projector = projector
        self.targets: dict[str, np.ndarray] = dict(targets or {})
        self.truth = truth
        self.closed = False

    @property
    def fingerprint(self) -> dict:
        """What a calibration of this rig depends on (:attr:`engine.rig.RigLike.fingerprint`).

        The backend, the identity, both resolutions, and whatever the camera and projector
        report about themselves in their own ``fingerprint`` dicts (model, serial, screen).
        """
        out = {"backend": self.identity.partition(":")[0], "rig": self.identity,
               "camera resolution": [int(v) for v in self.camera.resolution],
               "projector resolution": [int(v) for v in self.projector.resolution]}
        for part, device in (("camera", self.camera), ("projector", self.projector)):
            for key, value in (getattr(device, "fingerprint", None) or {}).items():
                out[f"{part} {key}"] = value
        out.update(self._fingerprint)
        return out

    def blank(self) -> None:
        """Show black on the projector (the safe state)."""
        hp, wp = self.projector.resolution
        self.projector.show(np.zeros((hp, wp, 3), np.float32))

    def close(self) -> None:
        """Leave the hardware safe: projector black, devices released. Idempotent."""
        if self.closed:
            return
        self.closed = True
        try:
            self.blank()
        finally:
            for dev in (self.projector, self.camera):
                close = getattr(dev, "close", None)
                if close is not None:
                    close()

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Rig({self.name!r}, camera={self.camera.resolution}, projector={self.projector.resolution})"
