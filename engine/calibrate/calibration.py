"""The calibration of one rig, as one value that round-trips through JSON plus plain arrays."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.calibrate._common import wh
from engine.calibrate.crosstalk import Crosstalk
from engine.calibrate.graycode import Correspondence
from engine.calibrate.response import ProjectorResponse
from engine.checks import check_image, check_resolution
from engine.errors import InputError
from engine.noise import CameraNoise
from engine.rig import fingerprint_differences

__all__ = ["CALIBRATION_VERSION", "Calibration"]

CALIBRATION_VERSION = 1
_KIND = "albedit.calibration"
#: Array names in :meth:`Calibration.to_dict` → (dtype, shape kind).
_ARRAYS = {
    "black_frame": (np.float32, "camera3"),
    "correspondence_x": (np.int32, "camera"),
    "correspondence_y": (np.int32, "camera"),
    "correspondence_status": (np.uint8, "camera"),
}


#: fingerprint entries said in words by :meth:`Calibration.check_compatible` itself
_RESOLUTION_KEYS = ("camera resolution", "projector resolution")


@dataclass(frozen=True, eq=False)
class Calibration:
    """Everything measured about a rig that acquisition needs.

    Attributes
    ----------
    rig_name : str
        The rig it was made with, e.g. ``"virtual:cornell"``.
    camera_resolution, projector_resolution : (H, W), (Hp, Wp)
    black_frame : (H, W, 3) float32
        Capture with the projector at black: ambient plus projector black light.
    response : ProjectorResponse
    correspondence : Correspondence
        Camera→projector pixels.
    crosstalk : Crosstalk or None
    metadata : dict
        JSON-serialisable facts (date, exposure, gain, settle delay, notes); ``"noise"`` the
        camera noise measured from repeated frames (:meth:`noise`).
    """

    rig_name: str
    camera_resolution: tuple[int, int]
    projector_resolution: tuple[int, int]
    black_frame: np.ndarray
    response: ProjectorResponse
    correspondence: Correspondence
    crosstalk: Crosstalk | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.rig_name, str) or not self.rig_name:
            raise InputError(f"rig_name must be a non-empty string, got {self.rig_name!r}")
        cam = check_resolution("camera_resolution", self.camera_resolution)
        proj = check_resolution("projector_resolution", self.projector_resolution)
        black = check_image("black_frame", self.black_frame, cam + (3,)).astype(np.float32, copy=True)
        black.flags.writeable = False
        if not isinstance(self.response, ProjectorResponse):
            raise InputError(f"response must be a ProjectorResponse, got {type(self.response).__name__}")
        if not isinstance(self.correspondence, Correspondence):
            raise InputError(f"correspondence must be a Correspondence, got {type(self.correspondence).__name__}")
        if self.correspondence.camera_resolution != cam or self.correspondence.projector_resolution != proj:
            raise InputError(
                f"correspondence maps a {wh(self.correspondence.camera_resolution)} camera to a "
                f"{wh(self.correspondence.projector_resolution)} projector, but the calibration is for camera "
                f"{wh(cam)} and projector {wh(proj)}"
            )
        if self.crosstalk is not None and not isinstance(self.crosstalk, Crosstalk):
            raise InputError(f"crosstalk must be a Crosstalk or None, got {type(self.crosstalk).__name__}")
        object.__setattr__(self, "camera_resolution", cam)
        object.__setattr__(self, "projector_resolution", proj)
        object.__setattr__(self, "black_frame", black)
        object.__setattr__(self, "metadata", dict(self.metadata))

    @property
    def noise(self) -> CameraNoise | None:
        """The camera's noise measured during calibration (None for calibrations without it)."""
        d = self.metadata.get("noise")
        return None if d is None else CameraNoise.from_dict(d)

    def check_compatible(self, rig_name: str, camera_resolution, projector_resolution,
                         fingerprint: dict | None = None) -> None:
        """Raise InputError saying why this calibration does not fit a rig.

        ``fingerprint`` is the rig's (:func:`engine.rig.fingerprint_of`); it is compared with
        the one recorded in ``metadata["rig_fingerprint"]`` when the calibration has one.

        Examples
        --------
        >>> cal = Calibration("virtual:box", (2, 2), (2, 2), np.zeros((2, 2, 3), np.float32),
        ...                   ProjectorResponse.linear(), Correspondence.identity((2, 2)))
        >>> cal.check_compatible("virtual:box", (2, 2), (2, 2))
        >>> cal.check_compatible("virtual:box", (480, 640), (2, 2))
        Traceback (most recent call last):
        ...
        engine.errors.InputError: calibration was made for camera 2×2, this rig's camera is 640×480; recalibrate
        """
        cam = check_resolution("camera_resolution", camera_resolution)
        proj = check_resolution("projector_resolution", projector_resolution)
        if rig_name != self.rig_name:
            raise InputError(
                f"calibration was made for rig {self.rig_name!r}, this rig is {rig_name!r}; recalibrate"
            )
        resolutions = []  # every difference in one message, so one recalibration fixes them all
        if cam != self.camera_resolution:
            resolutions.append(f"camera {wh(self.camera_resolution)}, this rig's camera is {wh(cam)}")
        if proj != self.projector_resolution:
            resolutions.append(f"projector {wh(self.projector_resolution)}, this rig's projector is {wh(proj)}")
        made_with = self.metadata.get("rig_fingerprint")
        others = []
        if fingerprint is not None and isinstance(made_with, dict):
            others = [d for d in fingerprint_differences(made_with, fingerprint) if not d.startswith(_RESOLUTION_KEYS)]
        if resolutions:
            raise InputError(f"calibration was made for {'; '.join(resolutions + others)}; recalibrate")
        if others:
            raise InputError(f"calibration was made with another set-up of rig {rig_name!r}: "
                             f"{'; '.join(others)}; recalibrate")

    def to_dict(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """Split into a JSON-serialisable description and named arrays (no pickle).

        Returns
        -------
        meta : dict
            JSON-ready; ``meta["arrays"]`` lists the array names with dtype and shape.
        arrays : dict[str, ndarray]
            ``black_frame`` (H, W, 3) float32, ``correspondence_x``/``_y`` (H, W) int32,
            ``correspondence_status`` (H, W) uint8. Store them in any lossless format.
        """
        arrays = {
            "black_frame": np.array(self.black_frame),
            "correspondence_x": np.array(self.correspondence.x),
            "correspondence_y": np.array(self.correspondence.y),
            "correspondence_status": np.array(self.correspondence.status),
        }
        meta = {
            "kind": _KIND,
            "version": CALIBRATION_VERSION,
            "rig_name": self.rig_name,
            "camera_resolution": list(self.camera_resolution),
            "projector_resolution": list(self.projector_resolution),
            "response": self.response.to_dict(),
            "crosstalk": None if self.crosstalk is None else self.crosstalk.to_dict(),
            "metadata": self.metadata,
            "arrays": {k: {"dtype": str(a.dtype), "shape": list(a.shape)} for k, a in arrays.items()},
        }
        return meta, arrays

    @classmethod
    def from_dict(cls, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> Calibration:
        """Rebuild from :meth:`to_dict`'s output, checking kind, version, dtypes and shapes.

        Examples
        --------
        >>> cal = Calibration("virtual:box", (2, 3), (2, 3), np.ones((2, 3, 3), np.float32),
        ...                   ProjectorResponse.linear(black_level=0.01), Correspondence.identity((2, 3)))
        >>> back = Calibration.from_dict(*cal.to_dict())
        >>> back.rig_name, back.response.black_level.tolist(), back.correspondence.x.tolist()
        ('virtual:box', [0.01, 0.01, 0.01], [[0, 1, 2], [0, 1, 2]])
        """
        if not isinstance(meta, dict) or meta.get("kind") != _KIND:
            kind = meta.get("kind") if isinstance(meta, dict) else None
            raise InputError(f"meta is not an Albedit calibration (kind {kind!r}, expected {_KIND!r})")
        if meta.get("version") != CALIBRATION_VERSION:
            raise InputError(
                f"calibration version {meta.get('version')!r} is not supported (this Albedit reads version "
                f"{CALIBRATION_VERSION}); recalibrate"
            )
        try:
            cam = check_resolution("camera_resolution", meta["camera_resolution"])
            proj = check_resolution("projector_resolution", meta["projector_resolution"])
            shapes = {"camera": cam, "camera3": cam + (3,)}
            got = {}
            for name, (dtype, kind) in _ARRAYS.items():
                if name not in arrays:
                    raise InputError(f"arrays is missing {name!r}")
                a = np.asarray(arrays[name])
                if a.dtype != dtype or a.shape != shapes[kind]:
                    raise InputError(
                        f"arrays[{name!r}] must be {np.dtype(dtype)} of shape {shapes[kind]}, "
                        f"got {a.dtype} {a.shape}"
                    )
                got[name] = a
            corr = Correspondence(
                got["correspondence_x"], got["correspondence_y"], got["correspondence_status"], proj
            )
            xt = meta.get("crosstalk")
            return cls(
                rig_name=meta["rig_name"],
                camera_resolution=cam,
                projector_resolution=proj,
                black_frame=got["black_frame"],
                response=ProjectorResponse.from_dict(meta["response"]),
                correspondence=corr,
                crosstalk=None if xt is None else Crosstalk.from_dict(xt),
                metadata=dict(meta.get("metadata") or {}),
            )
        except KeyError as e:
            raise InputError(f"meta is missing {e.args[0]!r}; not a complete calibration") from None
