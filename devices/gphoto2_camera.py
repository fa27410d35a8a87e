"""A tethered DSLR or mirrorless camera through libgphoto2 (python-gphoto2), RAW decoded linearly.

Install the optional extra: ``pip install albedit[gphoto2]`` (python-gphoto2; Linux and macOS).
The library is imported inside functions only, so Albedit runs without it.

Each capture triggers the camera, downloads the RAW file into memory, deletes it off the body
(best effort: bodies without a ``capturetarget`` keep every tethered shot in a buffer and refuse
triggers once it is full), and decodes it with rawpy without gamma, auto-brightening or white
balance. Trigger, download and delete run under one lock, and every library call has a
deadline (:class:`devices._common.Watchdog`). Exposure is settable: it snaps to the nearest
shutter speed the camera offers and :attr:`GPhoto2Camera.exposure` reports the value in use,
which is what the acquisition Recorder needs for HDR bracketing.

Rig names: ``"gphoto2"`` (the first camera found), ``"gphoto2:usb:001,004"`` (a port) or
``"gphoto2:Nikon DSC D7100"`` (a model as listed by :func:`list_cameras`).
"""

from __future__ import annotations

import math
import threading
from pathlib import PurePosixPath

import numpy as np

from devices._common import Watchdog, assemble_rig, call_with_timeout, check_positive
from devices._linearize import RAW_EXTENSIONS, decode_raw
from devices.base import Frame
from devices.registry import Availability
from engine.errors import DeviceError, InputError

__all__ = ["GPhoto2Camera", "list_cameras", "open_rig", "parse_shutter", "probe"]

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
}

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
    except ImportError:
        raise DeviceError("python-gphoto2 is not installed; install the optional extra: pip install 'albedit[gphoto2]'") from None
    return gphoto2


def device_error(exc: BaseException, what: str) -> DeviceError:
    """Turn a ``gphoto2.GPhoto2Error`` into a DeviceError in plain words.

    Examples
    --------
    >>> class GPhoto2Error(Exception):
    ...     code = -53
    >>> str(device_error(GPhoto2Error("[-53] Could not claim the USB device"), "opening the camera"))[:60]
    'opening the camera failed: the camera is claimed by another '
    """
    code = getattr(exc, "code", None)
    words = ERROR_WORDS.get(code, f"libgphoto2 error {code}: {exc}")
    return DeviceError(f"{what} failed: {words}")


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
    return [(str(name), str(port)) for name, port in found]


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
        gp=None,
    ):
        self._gp = _gphoto2() if gp is None else gp
        self.timeout = check_positive("timeout", timeout)
        self.delete = bool(delete)
        self.resolution = None if resolution is None else tuple(int(v) for v in resolution)
        self.warnings: list[str] = []
        self.settings: dict[str, str] = {}
        self.last_raw: bytes | None = None
        self.closed = False
        self._lock = threading.Lock()
        self._names: dict[str, str] = {}
        self.name = camera or ""
        self._dog = Watchdog(f"camera {camera}" if camera else "camera")
        self._cam = self._open(camera)
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
                    raise DeviceError(f"the camera's shutter speed is {current!r}; pass exposure= (seconds) to set a fixed one")
                self._exposure, self.settings["exposure"] = seconds, str(current)
            self._gain = self._read_gain(base_iso)
        except BaseException:
            self.close()
            raise

    # -- library calls with deadlines and plain-word errors -----------------------------
    def _call(self, fn, *args, what: str, timeout: float | None = None):
        try:
            return self._dog.call(fn, *args, timeout=timeout or self.timeout, what=what)
        except self._gp.GPhoto2Error as exc:
            raise device_error(exc, what) from None

    def _open(self, camera: str | None):
        gp = self._gp
        cam = self._call(gp.Camera, what="creating the camera handle")
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
        self._call(cam.init, what="opening the camera")
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

    def _choices(self, widget) -> list[str]:
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
                raws = [c for c in choices if c.upper().startswith(("RAW", "NEF", "CR2", "CR3", "ARW", "RAF", "ORF", "RW2", "DNG")) and "+" not in c and "JPEG" not in c.upper()]
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
        pairs = [(parse_shutter(c), c) for c in self._choices(self._config("exposure"))]
        pairs = sorted((s, c) for s, c in pairs if s is not None)
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
            raise DeviceError(f"ISO is {current!r}; pass iso= with a fixed value (choices: {', '.join(self._choices(widget))})")
        return float(current) / base

    # -- exposure and gain ----------------------------------------------------------------
    @property
    def exposure(self) -> float:
        """Exposure time in seconds actually set on the camera."""
        return self._exposure

    @exposure.setter
    def exposure(self, seconds: float) -> None:
        seconds = check_positive("exposure", seconds)
        target = math.log(seconds)
        value, text = min(self._shutters, key=lambda sc: abs(math.log(sc[0]) - target))
        if self.settings.get("exposure") != text:
            with self._lock:
                self._write("exposure", self._config("exposure"), text)
        self._exposure = value

    @property
    def gain(self) -> float:
        """Linear gain, ISO / base ISO (set it with the ``iso`` option)."""
        return self._gain

    # -- capturing ------------------------------------------------------------------------
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
            The camera failed or timed out (in plain words), delivered a non-RAW file, or an
            image of another size.
        """
        gp = self._gp
        with self._lock:
            if self.closed:
                raise DeviceError("the gphoto2 camera is closed")
            path = self._call(self._cam.capture, gp.GP_CAPTURE_IMAGE, what="capturing", timeout=self.timeout + self._exposure)
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
        if PurePosixPath(name).suffix.lower() not in RAW_EXTENSIONS:
            raise DeviceError(f"the camera delivered {name!r}, not a RAW file; set image_format='RAW' (RAW only, not RAW+JPEG)")
        self.last_raw = data
        try:
            raw = decode_raw(data)
        except DeviceError as exc:
            raise DeviceError(f"{name}: {exc}") from None
        h, w = raw.image.shape[:2]
        if self.resolution is None:
            self.resolution = (h, w)
        elif (h, w) != tuple(self.resolution):
            raise DeviceError(f"{name} is {w}x{h} pixels; the camera's images were {self.resolution[1]}x{self.resolution[0]}")
        scale = np.float32(1.0 / (self._exposure * self._gain))
        meta = {
            "backend": "gphoto2",
            "camera": self.name,
            "raw_name": name,
            "white_level": raw.white_level,
            "settings": dict(self.settings),
        }
        return Frame(image=raw.image * scale, exposure=self._exposure, gain=self._gain, black_level=raw.black_level, saturated=raw.saturated, metadata=meta)

    def close(self) -> None:
        """Release the camera (``exit``). Idempotent; errors while releasing are ignored."""
        if self.closed:
            return
        self.closed = True
        cam = getattr(self, "_cam", None)
        if cam is not None:
            try:
                self._call(cam.exit, what="releasing the camera", timeout=min(self.timeout, 10.0))
            except DeviceError:
                pass

    def __repr__(self) -> str:
        return f"GPhoto2Camera({self.name!r}, exposure={self._exposure:g}, resolution={self.resolution})"


def open_rig(arg: str = "", *, projector=None, settle: float | None = None, projector_timeout: float | None = None, **options):
    """Open ``"gphoto2"`` / ``"gphoto2:PORT_OR_MODEL"``: a tethered camera plus a projector window.

    Parameters
    ----------
    arg : str
        Port or model; empty for the first camera found.
    projector : str or Projector, optional
        ``"qtscreen:NAME_OR_INDEX"`` or a Projector; default the second screen.
    settle, projector_timeout : float, optional
        The projector window's settle time and paint timeout in seconds.
    **options
        :class:`GPhoto2Camera` options (``exposure``, ``iso``, ``aperture``, ...).
    """
    popts = {k: v for k, v in (("settle", settle), ("timeout", projector_timeout)) if v is not None}
    camera = GPhoto2Camera(arg or None, **options)
    return assemble_rig(f"gphoto2:{arg}" if arg else "gphoto2", camera, projector, **popts)


def probe(*, gp=None) -> list[Availability]:
    """The cameras libgphoto2 detects, or why none can be used."""
    try:
        cameras = list_cameras(gp=gp)
    except DeviceError as exc:
        return [Availability("gphoto2:", False, str(exc))]
    if not cameras:
        return [Availability("gphoto2:", False, "no camera detected (connected by USB, switched on, not in mass-storage mode?)")]
    return [Availability(f"gphoto2:{port}", True, model) for model, port in cameras]
