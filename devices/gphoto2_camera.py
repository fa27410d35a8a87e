"""A tethered DSLR or mirrorless camera through libgphoto2 (python-gphoto2), RAW decoded linearly.

Install the optional extra: ``pip install albedit[gphoto2]`` (python-gphoto2; Linux and macOS).
The library is imported inside functions only, so Albedit runs without it.

Each capture triggers the camera, downloads the RAW file into memory, deletes it off the body
(best effort: bodies without a ``capturetarget`` keep every tethered shot in a buffer and refuse
triggers once it is full), and decodes it with rawpy without gamma, auto-brightening or white
balance. Trigger, download and delete run under one lock, and every library call has a
deadline (:class:`devices._common.Watchdog`). Exposure is settable: it snaps to the nearest
shutter speed the camera offers and :attr:`GPhoto2Camera.exposure` reports the value in use,
which is what the acquisition Recorder needs for HDR bracketing (the one HDR merge: this
backend takes single shots).

Only python-gphoto2's supported API is used (checked against 2.6.4): the camera list through
``CameraList.items()`` (its iteration is deprecated since 2.6.1), ``file_get`` without a
``CameraFile`` argument, and a fresh ``Camera`` handle for every session (re-initialising a
handle after ``exit()`` fails with libgphoto2's virtual USB camera and corrupts its memory).

Rig names: ``"gphoto2"`` (the first camera found), ``"gphoto2:usb:001,004"`` (a port) or
``"gphoto2:Nikon DSC D7100"`` (a model as listed by :func:`list_cameras`).

Over 500 lines on purpose: every call into libgphoto2 (listing, opening, configuration widgets,
capture, download, reconnect) stays in this one module, the only one that knows its API.
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import PurePosixPath
from typing import Any

import numpy as np

from devices._common import DeviceTimeout, Watchdog, call_with_timeout
from devices.base import Frame
from devices.registry import Availability
from engine.checks import check_positive
from engine.errors import DeviceError, InputError
from engine.raw import RAW_EXTENSIONS, decode_raw

__all__ = ["GPhoto2Camera", "list_cameras", "open_camera", "parse_shutter", "probe"]

#: libgphoto2 error codes -> what to tell the user
ERROR_WORDS = {
    -105: "no camera found: check that it is connected by USB, switched on, awake and not in mass-storage mode",
    -52: "the camera's USB device could not be found or claimed: another program holds it (a desktop photo "
    "importer or volume monitor such as gvfs-gphoto2-volume-monitor); close that program or unmount the camera",
    -53: "the camera is claimed by another program (a desktop photo importer or volume monitor such as "
    "gvfs-gphoto2-volume-monitor); close that program or unmount the camera",
    -110: "the camera is busy (still writing, focusing or showing a menu); wait and try again",
    -10: "the camera did not answer in time; check the cable and that it is not asleep",
    -7: "input/output error talking to the camera; check the USB cable and port, then reconnect",
    -60: "could not lock the camera's USB device: another program holds it; close that program",
    -115: "the camera has no space left (card or internal buffer full); delete images on the camera, "
    "or use capture_target='Internal RAM'",
}

#: errors after which the session is closed and re-opened on the next capture (exit, init)
_RECONNECT = {-1, -7, -10, -52, -53, -60, -105, -110}

# config names differ between drivers; the first one the camera has is used
_NAMES = {
    "exposure": ("shutterspeed", "shutterspeed2", "exposuretime"),
    "iso": ("iso", "isospeed"),
    "aperture": ("aperture", "f-number", "fnumber"),
    "image_format": ("imageformat", "imagequality", "raw", "recordingmedia"),
    "capture_target": ("capturetarget",),
}


def _gphoto2():
    try:
        import gphoto2
    except ModuleNotFoundError as exc:
        if exc.name != "gphoto2":
            raise DeviceError(f"python-gphoto2 cannot be imported: {exc}") from None
        raise DeviceError("python-gphoto2 is not installed; "
                          "install the optional extra: pip install 'albedit[gphoto2]'") from None
    except ImportError as exc:  # installed, but libgphoto2 does not load
        raise DeviceError(f"python-gphoto2 cannot be imported: {exc}") from None
    return gphoto2


class GPhoto2DeviceError(DeviceError):
    """A :class:`DeviceError` from libgphoto2 that keeps its error code (the reconnect rule reads it)."""

    gphoto2_code: int | None = None


def device_error(exc: BaseException, what: str) -> GPhoto2DeviceError:
    """Turn a ``gphoto2.GPhoto2Error`` into a DeviceError in plain words.

    Examples
    --------
    >>> class GPhoto2Error(Exception):
    ...     code = -53
    >>> str(device_error(GPhoto2Error("[-53] Could not claim the USB device"), "opening the camera"))[:60]
    'opening the camera failed: the camera is claimed by another '
    """
    code = getattr(exc, "code", None)
    unknown = f"libgphoto2 error {code}: {exc}"
    words = unknown if code is None else ERROR_WORDS.get(code, unknown)
    err = GPhoto2DeviceError(f"{what} failed: {words}")
    err.gphoto2_code = code
    return err


def parse_shutter(text: str) -> float | None:
    """Seconds of a gphoto2 shutter-speed choice, or None for "bulb", "auto" and the like.

    Examples
    --------
    >>> parse_shutter("1/250"), parse_shutter("0.5"), parse_shutter("30s"), parse_shutter('2"'), parse_shutter("bulb")
    (0.004, 0.5, 30.0, 2.0, None)
    """
    s = str(text).strip().lower().rstrip('s"').strip()
    try:
        if "/" in s:
            num, den = s.split("/", 1)
            value = float(num) / float(den)
        else:
            value = float(s)
    except (ValueError, ZeroDivisionError):
        return None
    return value if math.isfinite(value) and value > 0 else None


def list_cameras(*, gp=None, timeout: float = 10.0) -> list[tuple[str, str]]:
    """``[(model, port), ...]`` of the cameras libgphoto2 detects.

    Raises
    ------
    DeviceError
        python-gphoto2 missing, or detection failed or timed out.
    """
    gp = _gphoto2() if gp is None else gp
    try:
        found = call_with_timeout(gp.Camera.autodetect, timeout=timeout, what="listing cameras", device="gphoto2")
    except gp.GPhoto2Error as exc:
        raise device_error(exc, "listing cameras") from None
    return [(str(name), str(port)) for name, port in found.items()]


class GPhoto2Camera:
    """A camera driven through libgphoto2, delivering linear radiance from its RAW files.

    Parameters
    ----------
    camera : str, optional
        Port (``"usb:001,004"``) or model name from :func:`list_cameras`; default the first camera.
    exposure : float, optional
        Exposure time in seconds, snapped to the nearest shutter speed offered.
    iso : int or str, optional
        ISO, one of the camera's choices (an error lists them).
    aperture : str or float, optional
        f-number, one of the camera's choices (``"5.6"``).
    image_format : str or None
        Value of the image-format setting, default ``"RAW"``; ``None`` leaves it alone.
    capture_target : str or None
        Value of ``capturetarget``; default ``"Internal RAM"`` (nothing is written to the card);
        ``None`` leaves it alone. Ignored when the camera has no such setting.
    base_iso : float, optional
        ISO that counts as gain 1 (default: the lowest numeric ISO choice, else 100).
    resolution : (H, W), optional
        Expected image size; otherwise set by the first capture.
    timeout : float
        Seconds any single libgphoto2 call may take (capture includes the exposure itself).
    delete : bool
        Delete each shot off the camera after download (best effort).
    release_after : float or None
        Seconds without a capture after which the camera session is released (``exit``); the
        next capture reconnects and re-applies every setting. Some bodies hang on the next
        connection when a session is left open. ``None`` keeps it open until :meth:`close`.
    gp : module, optional
        The ``gphoto2`` module (tests inject a scripted stand-in).

    Attributes
    ----------
    last_raw : bytes or None
        The original RAW file of the last capture, unchanged.
    settings : dict
        The config values in use (shutter speed text, ISO, aperture, format, target).
    warnings : list of str
        Settings the camera does not have, shots it refused to delete.
    """

    def __init__(
        self,
        camera: str | None = None,
        *,
        exposure: float | None = None,
        iso=None,
        aperture=None,
        image_format: str | None = "RAW",
        capture_target: str | None = "Internal RAM",
        base_iso: float | None = None,
        resolution=None,
        timeout: float = 30.0,
        delete: bool = True,
        release_after: float | None = 30.0,
        gp=None,
    ):
        self._gp = _gphoto2() if gp is None else gp
        self.timeout = check_positive("timeout", timeout)
        self.delete = bool(delete)
        self.resolution = None if resolution is None else tuple(int(v) for v in resolution)
        self.warnings: list[str] = []
        self.settings: dict[str, str] = {}
        self.last_raw: bytes | None = None
        self.release_after = check_positive("release_after", release_after, allow_none=True)
        self.closed = False
        self._session_open = False
        self._idle_timer: threading.Timer | None = None
        self._last_use = 0.0
        self._lock = threading.Lock()
        self._names: dict[str, str] = {}
        self.name = camera or ""
        #: what a calibration depends on (engine.rig.RigLike.fingerprint): the body it was opened as
        self.fingerprint = {"camera": self.name or "the first camera found"}
        self._dog = Watchdog(f"camera {camera}" if camera else "camera")
        self._cam: Any = None  # a gphoto2.Camera once open (the library is untyped)
        self._cam = self._open(camera)
        self._session_open = True
        try:
            if capture_target is not None:
                self._set_optional("capture_target", capture_target)
            if image_format is not None:
                self._set_choice("image_format", image_format)
            if iso is not None:
                self._set_choice("iso", iso)
            if aperture is not None:
                self._set_choice("aperture", aperture)
            self._shutters = self._shutter_choices()
            if exposure is not None:
                self.exposure = exposure
            else:
                current = self._config("exposure").get_value()
                seconds = parse_shutter(current)
                if seconds is None:
                    raise DeviceError(f"the camera's shutter speed is {current!r}; "
                                      "pass exposure= (seconds) to set a fixed one")
                self._exposure, self.settings["exposure"] = seconds, str(current)
            self._gain = self._read_gain(base_iso)
        except BaseException:
            self.close()
            raise
        self._schedule_release()

    # -- library calls with deadlines and plain-word errors -----------------------------
    def _call(self, fn, *args, what: str, timeout: float | None = None):
        try:
            return self._dog.call(fn, *args, timeout=timeout or self.timeout, what=what)
        except self._gp.GPhoto2Error as exc:
            raise device_error(exc, what) from None

    def _open(self, camera: str | None):
        gp = self._gp
        cam = self._call(gp.Camera, what="creating the camera handle")
        port = None
        if camera:
            port = camera
            if ":" not in camera or camera.split(":", 1)[0] not in ("usb", "ptpip", "serial", "disk"):
                models = list_cameras(gp=gp, timeout=self.timeout)
                matches = [p for m, p in models if m == camera]
                if not matches:
                    listing = ", ".join(f"{m} at {p}" for m, p in models) or "none"
                    raise DeviceError(f"no camera {camera!r} found; cameras found: {listing}")
                port = matches[0]
            ports = self._call(gp.PortInfoList, what="listing ports")
            self._call(ports.load, what="listing ports")
            index = self._call(ports.lookup_path, port, what=f"finding port {port}")
            self._call(cam.set_port_info, ports[index], what=f"selecting port {port}")
        self._call(cam.init, what=f"opening the camera at {port}" if camera else "opening the camera")
        return cam

    def _config(self, key: str):
        """The camera's config widget for ``key`` (trying each driver's name)."""
        if key in self._names:
            return self._call(self._cam.get_single_config, self._names[key], what=f"reading {self._names[key]}")
        for name in _NAMES[key]:
            try:
                widget = self._dog.call(self._cam.get_single_config, name, timeout=self.timeout, what=f"reading {name}")
            except self._gp.GPhoto2Error:
                continue
            self._names[key] = name
            return widget
        raise DeviceError(f"the camera has no {key.replace('_', ' ')} setting (tried {', '.join(_NAMES[key])})")

    @staticmethod
    def _choices(widget) -> list[str]:
        return [str(c) for c in widget.get_choices()]

    def _write(self, key: str, widget, value: str) -> None:
        widget.set_value(value)
        name = self._names[key]
        self._call(self._cam.set_single_config, name, widget, what=f"setting {name} to {value!r}")
        self.settings[key] = value

    def _set_choice(self, key: str, value, widget=None) -> None:
        widget = self._config(key) if widget is None else widget
        choices = self._choices(widget)
        text = str(value)
        if text not in choices:
            low = {c.lower(): c for c in choices}
            alt = text.lower().removeprefix("f/")
            text = low.get(text.lower()) or low.get(alt) or low.get(f"f/{alt}") or ""
            if not text and key == "image_format" and str(value).upper() == "RAW":
                raw_names = ("RAW", "NEF", "CR2", "CR3", "ARW", "RAF", "ORF", "RW2", "DNG")
                raws = [c for c in choices
                        if c.upper().startswith(raw_names) and "+" not in c and "JPEG" not in c.upper()]
                text = raws[0] if raws else ""
            if not text:
                raise InputError(f"{key} {value!r} is not offered by this camera; valid choices: {', '.join(choices)}")
        self._write(key, widget, text)

    def _set_optional(self, key: str, value) -> None:
        try:
            widget = self._config(key)
        except DeviceError as exc:
            self.warnings.append(f"{exc}; shots stay in the camera's buffer until deleted")
            return
        self._set_choice(key, value, widget)

    def _shutter_choices(self) -> list[tuple[float, str]]:
        parsed = [(parse_shutter(c), c) for c in self._choices(self._config("exposure"))]
        pairs = sorted((s, c) for s, c in parsed if s is not None)
        if not pairs:
            raise DeviceError("the camera offers no fixed shutter speeds (set the mode dial to M)")
        return pairs

    def _read_gain(self, base_iso: float | None) -> float:
        try:
            widget = self._config("iso")
        except DeviceError:
            self.warnings.append("the camera has no ISO setting: gain recorded as 1")
            return 1.0
        numeric = [float(c) for c in self._choices(widget) if c.replace(".", "", 1).isdigit()]
        base = float(base_iso) if base_iso is not None else (min(numeric) if numeric else 100.0)
        current = str(widget.get_value())
        self.settings["iso"] = current
        if not current.replace(".", "", 1).isdigit():
            raise DeviceError(f"ISO is {current!r}; pass iso= with a fixed value "
                              f"(choices: {', '.join(self._choices(widget))})")
        return float(current) / base

    # -- exposure and gain ----------------------------------------------------------------
    @property
    def exposure(self) -> float:
        """Exposure time in seconds actually set on the camera."""
        return self._exposure

    @exposure.setter
    def exposure(self, seconds: float) -> None:
        seconds = check_positive("exposure", seconds)
        shortest, longest = self._shutters[0], self._shutters[-1]
        if not shortest[0] / math.sqrt(2) <= seconds <= longest[0] * math.sqrt(2):
            raise InputError(
                f"exposure {seconds:g} s is outside the camera's shutter speeds "
                f"({shortest[1]} .. {longest[1]} s); valid choices: {', '.join(c for _, c in self._shutters)}"
            )
        target = math.log(seconds)
        value, text = min(self._shutters, key=lambda sc: abs(math.log(sc[0]) - target))
        if self.settings.get("exposure") != text:
            with self._lock:
                self._ensure_session()
                self._write("exposure", self._config("exposure"), text)
        self._exposure = value

    @property
    def gain(self) -> float:
        """Linear gain, ISO / base ISO (set it with the ``iso`` option)."""
        return self._gain

    # -- the session ----------------------------------------------------------------------
    def _ensure_session(self) -> None:
        """(Re)connect after an idle release or an error, and re-apply every setting."""
        if self._dog.recovered:  # an abandoned call came back: the session state is unknown
            self._dog.recovered = False
            self._drop_session()
        if self._session_open:
            return
        self._cam = self._open(self.name or None)  # a fresh handle: never init() one after exit()
        self._session_open = True
        for key, value in list(self.settings.items()):  # some bodies forget settings per session
            self._write(key, self._config(key), value)

    def _drop_session(self) -> None:
        """Best-effort ``exit`` so the next capture starts a fresh session."""
        try:
            self._dog.call(self._cam.exit, timeout=min(self.timeout, 10.0), what="releasing the camera")
        except self._gp.GPhoto2Error:
            pass
        except DeviceError:  # a call is still stuck in the library: cannot release now
            return
        self._session_open = False

    def _schedule_release(self) -> None:
        self._last_use = time.monotonic()
        if self.release_after is None:
            return
        if self._idle_timer is not None:
            self._idle_timer.cancel()
        self._idle_timer = threading.Timer(self.release_after, self._release_if_idle)
        self._idle_timer.daemon = True
        self._idle_timer.start()

    def _release_if_idle(self) -> None:
        if not self._lock.acquire(blocking=False):
            return  # a capture is running; it schedules the next release itself
        try:
            idle = time.monotonic() - self._last_use
            after = self.release_after  # not None: the release timer runs only with one
            if not self.closed and self._session_open and after is not None and idle >= after * 0.99:
                self._drop_session()
        finally:
            self._lock.release()

    def release(self) -> None:
        """Release the camera session now; the next capture reconnects (settings kept)."""
        with self._lock:
            if self._session_open and not self.closed:
                self._drop_session()

    @property
    def connected(self) -> bool:
        """Whether a libgphoto2 session is open (False after an idle release or an error)."""
        return self._session_open

    # -- capturing ------------------------------------------------------------------------
    def _shoot(self) -> tuple[str, bytes]:
        """Trigger, download and delete one shot (caller holds the lock)."""
        gp = self._gp
        try:
            self._ensure_session()
            path = self._call(self._cam.capture, gp.GP_CAPTURE_IMAGE, what="capturing",
                              timeout=self.timeout + self._exposure)
            folder, name = str(path.folder), str(path.name)
            try:
                cfile = self._call(self._cam.file_get, folder, name, gp.GP_FILE_TYPE_NORMAL, what=f"downloading {name}")
                data = bytes(memoryview(cfile.get_data_and_size()))
            finally:
                if self.delete:
                    try:
                        self._call(self._cam.file_delete, folder, name, what=f"deleting {name} from the camera")
                    except DeviceError as exc:  # some bodies refuse: harmless
                        self.warnings.append(str(exc))
        except DeviceError as exc:
            if getattr(exc, "gphoto2_code", None) in _RECONNECT or isinstance(exc, DeviceTimeout):
                self._drop_session()  # unplugged, timed out, claimed: start afresh next time
            raise
        if PurePosixPath(name).suffix.lower() not in RAW_EXTENSIONS:
            raise DeviceError(f"the camera delivered {name!r}, not a RAW file; "
                              "set image_format='RAW' (RAW only, not RAW+JPEG)")
        return name, data

    def _decode(self, name: str, data: bytes):
        try:
            raw = decode_raw(data, name=name)
        except InputError as exc:
            raise DeviceError(str(exc)) from None
        h, w = raw.image.shape[:2]
        if self.resolution is None:
            self.resolution = (h, w)
        elif (h, w) != tuple(self.resolution):
            raise DeviceError(f"{name} is {w}x{h} pixels; "
                              f"the camera's images were {self.resolution[1]}x{self.resolution[0]}")
        return raw

    def capture(self) -> Frame:
        """Trigger, download the RAW file to memory, delete it off the camera, decode linearly.

        Returns
        -------
        Frame
            ``image`` = linear RAW (black removed, white level = 1) / (exposure * gain);
            ``saturated`` where a photosite clipped; metadata ``raw_name`` and the settings.

        Raises
        ------
        DeviceError
            The camera failed or timed out (in plain words; the session is re-opened on the
            next capture), delivered a non-RAW file, or an image of another size.
        """
        with self._lock:
            if self.closed:
                raise DeviceError("the gphoto2 camera is closed")
            if self._idle_timer is not None:
                self._idle_timer.cancel()
            try:
                name, data = self._shoot()
                self.last_raw = data
                raw = self._decode(name, data)
            finally:
                self._schedule_release()
        meta = {
            "backend": "gphoto2",
            "camera": self.name,
            "raw_name": name,
            "white_level": raw.white_level,
            "settings": dict(self.settings),
        }
        image = raw.image / np.float32(self._exposure * self._gain)
        return Frame(image=image, exposure=self._exposure, gain=self._gain, black_level=raw.black_level,
                     saturated=raw.saturated, metadata=meta)

    def close(self) -> None:
        """Release the camera (``exit``). Idempotent; errors while releasing are ignored."""
        if self.closed:
            return
        self.closed = True
        if self._idle_timer is not None:
            self._idle_timer.cancel()
        if getattr(self, "_cam", None) is not None and self._session_open:
            try:
                self._call(self._cam.exit, what="releasing the camera", timeout=min(self.timeout, 10.0))
            except DeviceError:
                pass
            self._session_open = False

    def __repr__(self) -> str:
        return f"GPhoto2Camera({self.name!r}, exposure={self._exposure:g}, resolution={self.resolution})"


def open_camera(arg: str = "", **options) -> GPhoto2Camera:
    """Open ``"gphoto2"`` / ``"gphoto2:PORT_OR_MODEL"``: a :class:`GPhoto2Camera` (the first camera found
    when ``arg`` is empty); :func:`devices.open_rig` pairs it with a projector."""
    return GPhoto2Camera(arg or None, **options)


def probe(*, gp=None) -> list[Availability]:
    """The cameras libgphoto2 detects, or why none can be used."""
    try:
        cameras = list_cameras(gp=gp)
    except DeviceError as exc:
        return [Availability("gphoto2", False, str(exc))]
    if not cameras:
        return [Availability("gphoto2", False,
                             "no camera detected (connected by USB, switched on, not in mass-storage mode?)")]
    return [Availability(f"gphoto2:{port}", True, model) for model, port in cameras]
