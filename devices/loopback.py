"""A loopback bench: the real projector window and the real hot-folder camera, closed by a simulated camera.

``devices.open_rig("loopback:cornell")`` opens the projector as a full-screen :mod:`devices.qtscreen`
window (on the second screen; ``projector="qtscreen:HDMI-1"`` chooses another) and the camera as
a :mod:`devices.hotfolder` camera on a folder, fired by its trigger command. Where a lab's camera
would stand, a *bench camera* thread waits for that trigger; then it grabs what the projector's
screen displays (:meth:`~devices.qtscreen.QtScreenProjector.grab_screen`), lights the virtual
scene with it through the virtual rig's projector model, light transport and realistic sensor
(:mod:`devices.virtual`, the same scene and geometry), and saves the shot into the folder as a
tethered camera would: a 16-bit linear TIFF (default), a linear DNG (raw values, with black and
white level in the file) or an EXR, written in pieces. Calibration and capture thus run through
screen selection, full-screen geometry, the settle wait, the trigger, folder watching, file
completion checks, decoding and linearisation exactly as on a lab bench; only the light is
simulated.

Units: the sensor is the virtual rig's realistic one (shot and read noise, black level, 14-bit
ADC, clipping) with its photon scale set so that a file's full scale is radiance 1 per second of
exposure, and its exposure set to collect as many electrons per unit radiance as the virtual
rig's camera at its default exposure. Frames are therefore in the virtual rig's radiance units
with its noise, and ``rig.truth`` is the virtual rig's.

Faults, for tests (``faults={shot: kind}``, shots counted from 1): ``"drop"`` saves nothing (the
frame never arrives), ``"partial"`` saves half a file and stops, ``"twice"`` saves the shot twice
(a camera that fired twice: the next capture would take a frame of this pattern), ``"close"``
closes the projector window after saving (as a user would).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
import struct
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np

from devices.base import Rig
from devices.hotfolder import HotFolderCamera
from devices.registry import Availability, default_projector_problem, open_projector
from engine.errors import DeviceError, InputError
from engine.imageio import write_image

__all__ = ["BenchCamera", "LoopbackRig", "OFFSCREEN_SCREENS", "linear_dng", "offscreen_platform", "open_rig", "probe"]

#: Qt's offscreen platform configured as a bench: a 1920x1080 laptop panel and a 1024x768 projector,
#: ``HDMI-1``, beside it (the offscreen platform adds screens in the order of their names and
#: makes the first one primary, so the panel's name sorts first)
OFFSCREEN_SCREENS = [
    {"name": "Built-in display", "x": 0, "y": 0, "width": 1920, "height": 1080,
     "logicalDpi": 96, "logicalBaseDpi": 96, "dpr": 1},
    {"name": "HDMI-1", "x": 1920, "y": 0, "width": 1024, "height": 768,
     "logicalDpi": 96, "logicalBaseDpi": 96, "dpr": 1},
]


def offscreen_platform(folder, screens=OFFSCREEN_SCREENS) -> str:
    """Write ``screens`` as an offscreen-platform configuration into ``folder``; return the
    ``QT_QPA_PLATFORM`` value that uses it (set it before the Qt application starts).

    Examples
    --------
    >>> import tempfile
    >>> offscreen_platform(tempfile.mkdtemp()).startswith("offscreen:configfile=")
    True
    """
    path = Path(folder) / "screens.json"
    path.write_text(json.dumps({"screens": list(screens)}))
    return f"offscreen:configfile={path}"


#: file formats the bench camera saves, and their extensions
FORMATS = {"tiff": ".tif", "dng": ".dng", "exr": ".exr"}
FAULTS = ("drop", "partial", "twice", "close")

_OPTIONS = ("projector", "settle", "projector_timeout", "resolution", "folder", "file_format", "timeout", "poll",
            "quiet", "seed", "cache_dir", "patch_size", "supersample", "faults")

# the trigger: a command that leaves a "shutter" file for the bench camera (no shell, any OS)
_SHUTTER = "import sys; open(sys.argv[1], 'a').close()"


def linear_dng(raw: np.ndarray, *, black: int, white: int) -> bytes:
    """An uncompressed linear DNG (three values per pixel, camera RGB) of raw sensor values.

    Parameters
    ----------
    raw : (H, W, 3) uint16
        Raw values, black level included.
    black, white : int
        The sensor's black and white (clipping) level, stored in the file.

    Returns
    -------
    bytes
        A little-endian TIFF/DNG whose directory comes last, so a file cut short before its
        last 4 bytes is unreadable rather than silently incomplete.
    """
    raw = np.ascontiguousarray(raw, dtype="<u2")
    h, w, c = raw.shape
    data = raw.tobytes()
    entries = []

    def add(tag, typ, values):
        if typ == 2:
            payload, count = values.encode("ascii") + b"\0", len(values) + 1
        elif typ in (5, 10):
            payload, count = b"".join(struct.pack("<II" if typ == 5 else "<ii", *v) for v in values), len(values)
        else:
            code = {1: "B", 3: "H", 4: "I"}[typ]
            payload, count = struct.pack(f"<{len(values)}{code}", *values), len(values)
        entries.append((tag, typ, count, payload))

    add(254, 4, [0])  # NewSubFileType: the main image
    add(256, 4, [w])
    add(257, 4, [h])
    add(258, 3, [16] * c)  # BitsPerSample
    add(259, 3, [1])  # no compression
    add(262, 3, [34892])  # PhotometricInterpretation: LinearRaw
    add(271, 2, "Albedit")
    add(272, 2, "Loopback bench camera")
    add(273, 4, [8])  # the strip follows the header
    add(274, 3, [1])  # Orientation
    add(277, 3, [c])
    add(278, 4, [h])
    add(279, 4, [len(data)])
    add(284, 3, [1])
    add(50706, 1, [1, 4, 0, 0])  # DNGVersion
    add(50707, 1, [1, 1, 0, 0])
    add(50708, 2, "Albedit Loopback")
    add(50714, 4, [int(black)] * c)
    add(50717, 4, [int(white)] * c)
    add(50721, 10, [(1, 1), (0, 1), (0, 1), (0, 1), (1, 1), (0, 1), (0, 1), (0, 1), (1, 1)])  # ColorMatrix1: identity
    add(50728, 5, [(1, 1)] * c)  # AsShotNeutral
    add(50778, 3, [21])  # CalibrationIlluminant1: D65
    entries.sort()
    extra_at = 8 + len(data) + len(data) % 2
    extra = b""
    table = b""
    for tag, typ, count, payload in entries:
        if len(payload) <= 4:
            table += struct.pack("<HHI", tag, typ, count) + payload.ljust(4, b"\0")
        else:
            table += struct.pack("<HHI", tag, typ, count) + struct.pack("<I", extra_at + len(extra))
            extra += payload + b"\0" * (len(payload) % 2)
    ifd_at = extra_at + len(extra)
    ifd = struct.pack("<H", len(entries)) + table + struct.pack("<I", 0)
    return b"II*\0" + struct.pack("<I", ifd_at) + data + b"\0" * (len(data) % 2) + extra + ifd


class BenchCamera:
    """The simulated camera of the loopback bench: photographs the scene lit by the screen.

    Parameters
    ----------
    projector : devices.qtscreen.QtScreenProjector
        The real projector window; the camera sees what its screen displays.
    scene : devices.virtual.VirtualRig
        The virtual scene (its projector model, transport and camera sensor are used).
    folder : Path
        Where shots are saved (the hot folder).
    shutter : Path
        The file the trigger command creates to fire the camera.
    file_format : {"tiff", "dng", "exr"}
    faults : dict[int, str], optional
        Shot number (from 1) -> one of :data:`FAULTS`.
    chunks : int
        Pieces each file is written in (a tethering program streams it).

    Attributes
    ----------
    shots : list of dict
        One entry per shot: ``shot``, ``file`` (None when dropped), ``screen`` (SHA-1 of the
        screen codes it saw), ``fault``.
    errors : list of str
        Shots that failed (the screen could not be grabbed): nothing was saved for them.
    """

    def __init__(self, projector, scene, folder: Path, shutter: Path, *, file_format: str = "tiff", faults=None,
                 chunks: int = 4):
        self.projector, self.scene = projector, scene
        self.folder, self.shutter = Path(folder), Path(shutter)
        self.file_format, self.faults, self.chunks = file_format, dict(faults or {}), int(chunks)
        self.shots: list[dict] = []
        self.errors: list[str] = []
        self._scratch = Path(tempfile.mkdtemp(prefix="albedit-bench-"))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="albedit-bench-camera", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            if self.shutter.exists():
                self.shutter.unlink()
                self._shoot(len(self.shots) + 1)
            else:
                self._stop.wait(0.002)

    def _shoot(self, n: int) -> None:
        fault = self.faults.get(n)
        try:
            codes = self.projector.grab_screen()
        except DeviceError as exc:
            self.errors.append(f"shot {n}: {exc}")
            self.shots.append({"shot": n, "file": None, "screen": None, "fault": fault})
            return
        name = f"IMG_{n:04d}{FORMATS[self.file_format]}"
        self.shots.append({"shot": n, "file": None if fault == "drop" else name,
                           "screen": hashlib.sha1(codes.tobytes()).hexdigest(), "fault": fault})
        if fault == "drop":
            return
        data = self._encode(self._expose(codes))
        self._write(self.folder / name, data[: len(data) // 2] if fault == "partial" else data)
        if fault == "twice":
            self._write(self.folder / f"IMG_{n:04d}b{FORMATS[self.file_format]}", data)
        if fault == "close":
            window = self.projector.window
            self.projector.call_on_ui(window.close, what="close the projector window")

    def _expose(self, codes: np.ndarray) -> np.ndarray:
        """Raw sensor values (H, W, 3) of the scene lit by screen ``codes`` (the virtual rig's physics)."""
        self.scene.projector.show(codes.astype(np.float32) / np.float32(255.0))  # the same 8-bit levels
        frame = self.scene.camera.capture()
        model = self.scene.camera.model
        scale = frame.exposure * frame.gain * model.calibration
        return np.rint(frame.image.astype(np.float64) * scale + model.black_level)  # the sensor's integers

    def _encode(self, raw: np.ndarray) -> bytes:
        model = self.scene.camera.model
        black, white = model.black_level, model.white_level
        if self.file_format == "dng":
            return linear_dng(raw.astype(np.uint16), black=int(black), white=int(white))
        fraction = ((raw - black) / (white - black)).astype(np.float32)  # a linear RAW converter's output
        path = self._scratch / f"shot{FORMATS[self.file_format]}"
        if self.file_format == "tiff":
            write_image(path, np.clip(fraction, 0.0, 1.0), dtype="uint16", srgb=False)
        else:
            write_image(path, fraction)
        return path.read_bytes()

    def _write(self, target: Path, data: bytes) -> None:
        step = max(1, -(-len(data) // self.chunks))
        with open(target, "wb") as fh:
            for i in range(0, len(data), step):
                fh.write(data[i : i + step])
                fh.flush()

    def stop(self) -> None:
        """Stop waiting for the trigger and remove the scratch folder. Idempotent."""
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(5.0)
        shutil.rmtree(self._scratch, ignore_errors=True)


class LoopbackRig(Rig):
    """A :class:`devices.base.Rig` of a real projector window and a real hot-folder camera on a bench.

    Attributes
    ----------
    camera : devices.hotfolder.HotFolderCamera
    projector : devices.qtscreen.QtScreenProjector
    bench : BenchCamera
        The simulated camera that writes the files (its ``shots`` log, for tests).
    truth : devices.virtual.Truth
        The scene's ground truth, in the frames' units.
    scene : devices.virtual.VirtualRig
        The virtual scene the bench camera photographs.
    """

    def __init__(self, name, camera, projector, *, scene, bench: BenchCamera, owned: list[Path]):
        super().__init__(name, camera, projector, targets=scene.targets, truth=scene.truth)
        self.scene, self.bench = scene, bench
        self._owned = owned

    def close(self) -> None:
        """Leave the projector black, release both devices, stop the bench camera. Idempotent."""
        if self.closed:
            return
        try:
            super().close()
        finally:
            self.bench.stop()
            self.scene.close()
            for folder in self._owned:
                shutil.rmtree(folder, ignore_errors=True)


def _sensor(scene):
    """The bench camera's sensor: the virtual rig's, in radiance per second of exposure at full scale."""
    model = scene.camera.model
    full_scale = model.white_level - model.black_level
    bench = dataclasses.replace(model, electrons_per_radiance=model.electrons_per_dn * full_scale)
    exposure = scene.camera.exposure * model.electrons_per_radiance / bench.electrons_per_radiance
    return bench, exposure


def open_rig(arg: str, **options) -> LoopbackRig:
    """Open ``"loopback:SCENE"``: the loopback bench on a virtual scene (see the module notes).

    Parameters
    ----------
    arg : str
        A virtual scene name (``"cornell"``, ``"wedge"``, ``"three"``) or scene file.
    projector : str, optional
        The projector window's screen, ``"qtscreen:NAME_OR_INDEX"`` (default: the second screen).
    settle, projector_timeout : float
        The projector window's settle time and paint timeout, seconds (default 0.05, 5).
    resolution : (H, W)
        Camera resolution (default (48, 64): every frame is a real file).
    folder : str or Path, optional
        The hot folder (default: a fresh temporary folder, removed on close).
    file_format : {"tiff", "dng", "exr"}
        What the bench camera saves (default ``"tiff"``, 16-bit linear).
    timeout, poll, quiet : float
        The hot-folder camera's (seconds; defaults 10, 0.01, 2).
    seed : int
        The sensor noise seed (default 0, as the virtual rig's).
    cache_dir, patch_size
        As for the virtual rig.
    supersample : int
        Sub-samples per camera pixel edge (default 1). The bench's camera is much coarser than the
        projector window (64×48 against 1024×768: 16 projector pixels per camera pixel), so
        mixed pixels would average the finest Gray-code stripes away; the bench proves the device
        paths, and the virtual rig's own supersampling (default 4) shows the optics.
    faults : dict[int, str], optional
        Shot number -> fault (module notes).

    Returns
    -------
    LoopbackRig

    Raises
    ------
    InputError
        Unknown scene, option or fault; a projector that is not a screen window.
    DeviceError
        No screen for the projector.
    """
    unknown = sorted(set(options) - set(_OPTIONS))
    if unknown:
        raise InputError(f"unknown loopback rig option(s) {unknown}; expected some of {list(_OPTIONS)}")
    file_format = options.get("file_format", "tiff")
    if file_format not in FORMATS:
        raise InputError(f"file_format must be one of {sorted(FORMATS)}, got {file_format!r}")
    faults = dict(options.get("faults") or {})
    for shot, kind in faults.items():
        if kind not in FAULTS or isinstance(shot, bool) or not isinstance(shot, int) or shot < 1:
            raise InputError(f"faults must map shot numbers (from 1) to one of {list(FAULTS)}, got {shot!r}: {kind!r}")
    spec = options.get("projector")
    if spec is not None and not (isinstance(spec, str) and spec.partition(":")[0] == "qtscreen"):
        raise InputError(f"the loopback bench's projector is a screen window, 'qtscreen:NAME_OR_INDEX'; got {spec!r}")
    from devices import virtual

    projector = open_projector(spec, settle=options.get("settle", 0.05), timeout=options.get("projector_timeout", 5.0))
    owned: list[Path] = []
    scene = camera = None
    try:
        vopts: dict[str, Any] = {k: options[k] for k in ("seed", "cache_dir", "patch_size") if k in options}
        vopts["supersample"] = options.get("supersample", 1)
        resolution = options.get("resolution", (48, 64))
        scene = virtual.open_rig(arg, resolution=resolution, projector_resolution=projector.resolution, **vopts)
        scene.camera.model, exposure = _sensor(scene)
        scene.camera.exposure = exposure
        folder = options.get("folder")
        if folder is None:
            folder = Path(tempfile.mkdtemp(prefix="albedit-loopback-"))
            owned.append(folder)
        control = Path(tempfile.mkdtemp(prefix="albedit-shutter-"))
        owned.append(control)
        shutter = control / "shutter"
        camera = HotFolderCamera(
            folder, resolution=scene.camera.resolution, exposure=exposure,
            timeout=options.get("timeout", 10.0), poll=options.get("poll", 0.01), quiet=options.get("quiet", 2.0),
            trigger=[sys.executable, "-I", "-S", "-c", _SHUTTER, str(shutter)], extensions=[FORMATS[file_format]],
        )
        camera.set_idle(projector.idle)
        bench = BenchCamera(projector, scene, Path(folder), shutter, file_format=file_format, faults=faults)
    except BaseException:
        projector.close()
        if scene is not None:
            scene.close()
        for path in owned:
            shutil.rmtree(path, ignore_errors=True)
        raise
    return LoopbackRig(f"loopback:{arg}", camera, projector, scene=scene, bench=bench, owned=owned)


def probe() -> list[Availability]:
    """The loopback bench needs a screen for its projector window (the second one by default)."""
    from devices.virtual import scene_names

    problem = default_projector_problem()
    note = f"; projector: {problem} (pass projector='qtscreen:0')" if problem else ""
    reason = "the real projector window and hot-folder camera on a simulated scene"
    return [Availability(f"loopback:{name}", not problem, reason + note) for name in scene_names()]

