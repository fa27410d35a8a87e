"""GenICam machine-vision cameras (GigE Vision, USB3 Vision) through ``harvesters``, linear.

Install the optional extra, ``pip install 'albedit[harvesters]'``, and the camera maker's GenTL
producer (a ``.cti`` file). The library is imported inside functions only.

Machine-vision sensors are linear when their gamma is off, so no response curve is needed:
the backend switches ``ExposureAuto``/``GainAuto`` off and ``GammaEnable`` off where the
camera has them, chooses the deepest linear pixel format it offers (Mono16 … Mono8,
Bayer*16 … Bayer*8, RGB16/RGB8), and sets ``ExposureTime`` (µs, validated against the
camera's range) by their SFNC names. Each capture starts acquisition, fetches one complete
frame with a deadline (``try_fetch``; harvesters' ``fetch`` can wait forever on incomplete
buffers), stops again — so every frame is exposed after the call began, never a frame queued
before a projector change — and demosaics Bayer data with OpenCV. The producer file is checked
when it is loaded (harvesters' ``add_file`` accepts an unloadable file silently by default,
and the camera list then comes back empty). A camera without ``ExposureTime`` delivers
radiance in relative units (exposure recorded as 1 s, not settable).

Rig name: ``"harvesters:/path/to/producer.cti"``, options ``serial=`` or ``index=`` to choose
the camera, ``exposure=`` in seconds, ``gain=`` linear.
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from devices._common import Watchdog
from devices.base import Frame
from devices.registry import Availability
from engine.checks import check_positive
from engine.errors import DeviceError, InputError

__all__ = ["HarvestersCamera", "open_camera", "probe"]

#: preferred pixel formats, deepest first (all linear when gamma is off)
PIXEL_FORMATS = tuple(
    f"{kind}{bits}"
    for bits in (16, 14, 12, 10, 8)
    for kind in ("Mono", "BayerRG", "BayerGB", "BayerGR", "BayerBG", "RGB")
)

# GenICam names a Bayer pattern by its first row; OpenCV by the second row's last two pixels
_BAYER_TO_CV = {"RG": "COLOR_BayerBG2RGB", "BG": "COLOR_BayerRG2RGB",
                "GR": "COLOR_BayerGB2RGB", "GB": "COLOR_BayerGR2RGB"}


#: harvesters' own log: it prints every failure with a traceback on stderr by default, and each
#: failure that matters reaches the user as a one-line DeviceError instead
LIBRARY_LOG = logging.getLogger(__name__ + ".library")
LIBRARY_LOG.propagate = False
LIBRARY_LOG.addHandler(logging.NullHandler())


def _harvesters_core():
    try:
        import harvesters.core as core
    except ModuleNotFoundError as exc:
        if exc.name not in ("harvesters", "harvesters.core", "genicam"):
            raise DeviceError(f"harvesters cannot be imported: {exc}") from None
        raise DeviceError(
            "harvesters is not installed; install the optional extra: pip install 'albedit[harvesters]' "
            "(and the camera maker's GenTL producer, a .cti file)"
        ) from None
    except ImportError as exc:  # installed, but a binary part does not load
        raise DeviceError(f"harvesters cannot be imported: {exc}") from None
    return core


def _new_harvester():
    """A ``Harvester`` that logs into :data:`LIBRARY_LOG` (its supported ``config`` parameter)."""
    core = _harvesters_core()
    return core.Harvester(config=core.ParameterSet({core.ParameterKey.LOGGER: LIBRARY_LOG}))


def _bits(pixel_format: str) -> int:
    """Significant bits of a GenICam pixel format name (``"Mono12"`` -> 12).

    Examples
    --------
    >>> _bits("BayerRG12"), _bits("RGB8")
    (12, 8)
    """
    m = re.search(r"(\d+)$", pixel_format)
    if m is None:
        raise DeviceError(f"unsupported pixel format {pixel_format!r}; expected one of {', '.join(PIXEL_FORMATS)}")
    return int(m.group(1))


def to_rgb(data: np.ndarray, pixel_format: str, width: int, height: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Turn one GenICam payload into RGB codes.

    Parameters
    ----------
    data : 1-D array
        The component's data (uint8 or uint16, one value per sample).
    pixel_format : str
        GenICam name (``Mono*``, ``Bayer**``, ``RGB*``; unpacked formats only).
    width, height : int

    Returns
    -------
    rgb : (H, W, 3) float64 codes
    clipped : (H, W) bool
        Where a sample reached the top code (grown to the 3x3 neighbours a demosaic mixes in).
    top : int
        The top code, 2**bits - 1.
    """
    import cv2

    bits = _bits(pixel_format)
    top = 2**bits - 1
    kind = pixel_format[: -len(str(bits))]
    if kind == "RGB":
        rgb = np.asarray(data).reshape(height, width, 3)
        return rgb.astype(np.float64), np.any(rgb >= top, axis=2), top
    mosaic = np.asarray(data).reshape(height, width)
    clipped = mosaic >= top
    if kind == "Mono":
        return np.repeat(mosaic[:, :, None], 3, axis=2).astype(np.float64), clipped, top
    if kind.startswith("Bayer") and kind[5:] in _BAYER_TO_CV:
        rgb = cv2.cvtColor(np.ascontiguousarray(mosaic.astype(np.uint16)), getattr(cv2, _BAYER_TO_CV[kind[5:]]))
        if clipped.any():
            clipped = cv2.dilate(clipped.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        return rgb.astype(np.float64), clipped, top
    raise DeviceError(f"unsupported pixel format {pixel_format!r}; expected one of {', '.join(PIXEL_FORMATS)}")


class HarvestersCamera:
    """A GenICam camera through harvesters, delivering linear radiance.

    Parameters
    ----------
    cti : str or Path
        The GenTL producer file of the camera maker.
    serial : str, optional
        Serial number of the camera to open; otherwise ``index``.
    index : int
        Position in the producer's device list.
    exposure : float, optional
        Exposure time in seconds (validated against the camera's ``ExposureTime`` range).
    gain : float, optional
        Linear gain; written to ``Gain`` in dB (20·log10) when the camera has it.
    pixel_format : str, optional
        A GenICam pixel format the camera offers; default the deepest linear one.
    black_level : float
        Code value of black, subtracted before scaling (measure it with the lens capped).
    timeout : float
        Seconds any one call, and the wait for a complete frame, may take.

    Attributes
    ----------
    resolution : (H, W)
    warnings : list of str
        Features the camera lacks or refused (auto exposure, gamma), recorded in metadata.
    """

    def __init__(
        self,
        cti,
        *,
        serial: str | None = None,
        index: int = 0,
        exposure: float | None = None,
        gain: float | None = None,
        pixel_format: str | None = None,
        black_level: float = 0.0,
        timeout: float = 5.0,
    ):
        cti_path = Path(cti)
        if not cti_path.is_file():
            raise DeviceError(f"no GenTL producer file at {str(cti_path)!r} (the camera maker's .cti)")
        self.timeout = check_positive("timeout", timeout)
        self.black_level = float(black_level)
        self.warnings: list[str] = []
        self.closed = False
        self._lock = threading.Lock()
        self._dog = Watchdog("GenICam camera")
        self._ia: Any = None  # harvesters' ImageAcquirer once the camera is open (the library is untyped)
        self._h = _new_harvester()
        try:
            self._call(self._h.add_file, str(cti_path), True, True, what="loading the GenTL producer")
            self._call(self._h.update, what="listing cameras")
            found = list(self._h.device_info_list)
            if not found:
                raise DeviceError(f"no GenICam camera found through {cti_path.name} "
                                  "(connected, powered, on this network?)")
            key = {"serial_number": str(serial)} if serial else int(index)
            if isinstance(key, int) and not 0 <= key < len(found):
                raise DeviceError(f"there is no camera {key}: {len(found)} found through {cti_path.name}")
            self._ia = self._call(self._h.create, key, what="opening the camera")
            self._nodes = self._ia.remote_device.node_map
            self._optional("ExposureAuto", "Off", "auto exposure could not be switched off")
            self._optional("GainAuto", "Off", "auto gain could not be switched off")
            self._optional("GammaEnable", False, "gamma could not be switched off: check the camera's output is linear")
            self.pixel_format = self._choose_format(pixel_format)
            self.resolution = (int(self._nodes.Height.value), int(self._nodes.Width.value))
            #: what a calibration depends on (engine.rig.RigLike.fingerprint)
            self.fingerprint = self._identity()
            if self._node("ExposureTime") is None:
                self.warnings.append("the camera has no ExposureTime feature: "
                                     "radiance is in relative units (exposure recorded as 1 s)")
            if exposure is not None:
                self.exposure = exposure
            if gain is not None:
                self.gain = gain
        except BaseException:
            self.close()
            raise

    # -- features -----------------------------------------------------------------------
    def _call(self, fn, *args, what: str):
        try:
            return self._dog.call(fn, *args, timeout=self.timeout, what=what)
        except DeviceError:
            raise
        except Exception as exc:  # genicam exceptions carry the producer's own words
            raise DeviceError(f"{what} failed: {exc}") from None

    def _identity(self) -> dict[str, str]:
        """Model and serial number: from the GenTL device module, else from the camera's own features."""
        module = getattr(getattr(self._ia, "device", None), "node_map", None)
        out = {}
        for key, feature in (("model", "DeviceModelName"), ("serial", "DeviceSerialNumber")):
            for nodes in (module, self._nodes):
                try:
                    out[key] = str(getattr(nodes, feature).value)
                    break
                except Exception:  # noqa: BLE001 - a producer without the feature raises its own type
                    continue
        return out

    def _node(self, name: str):
        try:
            return getattr(self._nodes, name)
        except Exception:  # harvesters raises LogicalErrorException for missing features
            return None

    def _write(self, name: str, value) -> None:
        node = self._node(name)
        if node is None:
            raise DeviceError(f"the camera has no {name} feature")

        def assign():
            node.value = value

        self._call(assign, what=f"setting {name} to {value!r}")

    def _optional(self, name: str, value, warning: str) -> None:
        if self._node(name) is None:
            return
        try:
            self._write(name, value)
        except DeviceError as exc:
            self.warnings.append(f"{warning} ({exc})")

    def _choose_format(self, wanted: str | None) -> str:
        node = self._node("PixelFormat")
        if node is None:
            raise DeviceError("the camera has no PixelFormat feature")
        offered = [str(s) for s in getattr(node, "symbolics", [])]
        if wanted is not None:
            if wanted not in offered:
                raise InputError(f"pixel_format {wanted!r} is not offered by this camera; "
                                 f"valid choices: {', '.join(offered)}")
            choice = wanted
        else:
            usable = [f for f in PIXEL_FORMATS if f in offered]
            if not usable:
                raise DeviceError(f"the camera offers no unpacked linear pixel format ({', '.join(offered)})")
            choice = usable[0]
        if str(node.value) != choice:
            self._write("PixelFormat", choice)
        return choice

    @property
    def node_map(self):
        """The camera's GenICam features by SFNC name, for the ones Albedit does not set itself."""
        return self._nodes

    @property
    def exposure(self) -> float:
        """Exposure time in seconds, as the camera reports it (1 without an ExposureTime feature)."""
        node = self._node("ExposureTime")
        return 1.0 if node is None else float(node.value) * 1e-6

    @exposure.setter
    def exposure(self, seconds: float) -> None:
        seconds = check_positive("exposure", seconds)
        node = self._node("ExposureTime")
        if node is None:
            raise DeviceError("the camera has no ExposureTime feature: its exposure cannot be set from here")
        lo, hi = float(node.min) * 1e-6, float(node.max) * 1e-6
        if not lo <= seconds <= hi:
            raise InputError(f"exposure {seconds:g} s is outside the camera's range {lo:g} .. {hi:g} s")
        with self._lock:
            self._write("ExposureTime", seconds * 1e6)

    @property
    def gain(self) -> float:
        """Linear gain (the SFNC ``Gain`` feature is in dB); 1 without the feature."""
        node = self._node("Gain")
        return 1.0 if node is None else 10.0 ** (float(node.value) / 20.0)

    @gain.setter
    def gain(self, value: float) -> None:
        value = check_positive("gain", value)
        node = self._node("Gain")
        if node is None:
            if value != 1.0:
                raise DeviceError("the camera has no Gain feature; only gain 1 is possible")
            return
        db = 20.0 * math.log10(value)
        lo, hi = float(node.min), float(node.max)
        if not lo - 1e-9 <= db <= hi + 1e-9:
            raise InputError(f"gain {value:g} ({db:.2f} dB) is outside the camera's range {lo:g} .. {hi:g} dB")
        with self._lock:
            self._write("Gain", db)

    # -- capturing ------------------------------------------------------------------------
    def _try_fetch(self, seconds: float):
        return self._ia.try_fetch(timeout=seconds)

    def _fetch_one(self):
        deadline = time.monotonic() + self.timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise DeviceError(
                    f"no complete frame from the camera within {self.timeout:g} s (unplugged, "
                    "a trigger mode left on, or too little network bandwidth?)"
                )
            buffer = self._call(self._try_fetch, min(left, 1.0), what="fetching a frame")
            if buffer is None:
                continue
            try:
                comp = buffer.payload.components[0]
                data = np.array(comp.data, copy=True)
                return data, str(comp.data_format), int(comp.width), int(comp.height)
            finally:
                buffer.queue()

    def capture(self) -> Frame:
        """Start acquisition, fetch one complete frame, stop; return linear radiance.

        Returns
        -------
        Frame
            ``image`` = (codes - black_level) / (top code - black_level) / (exposure * gain);
            ``saturated`` where a sample reached the top code.

        Raises
        ------
        DeviceError
            No complete frame within ``timeout``, the camera failed, or a frame of another size.
        """
        with self._lock:
            if self.closed:
                raise DeviceError("the GenICam camera is closed")
            self._call(self._ia.start, what="starting acquisition")
            try:
                data, fmt, w, h = self._fetch_one()
            finally:
                self._call(self._ia.stop, what="stopping acquisition")
            exposure, gain = self.exposure, self.gain
        if (h, w) != tuple(self.resolution):
            raise DeviceError(f"the camera delivered {w}x{h}; it was {self.resolution[1]}x{self.resolution[0]}")
        rgb, clipped, top = to_rgb(data, fmt, w, h)
        scale = 1.0 / ((top - self.black_level) * exposure * gain)
        image = ((rgb - self.black_level) * scale).astype(np.float32)
        meta = {"backend": "harvesters", "pixel_format": fmt, "top_code": top, "warnings": list(self.warnings)}
        return Frame(image=image, exposure=exposure, gain=gain, black_level=self.black_level, saturated=clipped,
                     metadata=meta)

    def close(self) -> None:
        """Destroy the image acquirer and reset the harvester. Idempotent; errors ignored."""
        if self.closed:
            return
        self.closed = True
        steps = []
        if self._ia is not None:
            steps.append((self._ia.destroy, "closing the camera"))
        steps.append((self._h.reset, "releasing the GenTL producer"))
        for fn, what in steps:
            try:
                self._call(fn, what=what)
            except DeviceError:
                pass

    def __repr__(self) -> str:
        return (f"HarvestersCamera(resolution={getattr(self, 'resolution', None)}, "
                f"pixel_format={getattr(self, 'pixel_format', None)!r})")


def open_camera(arg="", **options) -> HarvestersCamera:
    """Open ``"harvesters:/path/to/producer.cti"``: a :class:`HarvestersCamera` through that GenTL
    producer (:func:`devices.open_rig` pairs it with a projector).

    Raises
    ------
    InputError
        No producer file given.
    DeviceError
        harvesters missing, an unusable producer, or no camera.
    """
    if not str(arg):
        raise InputError("harvesters needs the GenTL producer: open_rig('harvesters:/path/to/producer.cti')")
    return HarvestersCamera(arg, **options)


def probe() -> list[Availability]:
    """Whether harvesters can be imported (cameras are listed only through a given producer file).

    Examples
    --------
    >>> probe()[0].name
    'harvesters:PRODUCER.cti'
    """
    try:
        _harvesters_core()
    except DeviceError as exc:
        return [Availability("harvesters:PRODUCER.cti", False, str(exc))]
    return [Availability("harvesters:PRODUCER.cti", True, "GenICam camera through the maker's GenTL producer (.cti)")]
