"""A camera whose captures arrive as files in a watched folder (vendor tethering software).

Many camera makers ship tethering programs (Canon EOS Utility, Nikon Camera Control Pro,
Capture One, Sony Imaging Edge) that save each shot into a folder. This backend watches that
folder: :meth:`HotFolderCamera.capture` optionally runs a trigger command, then waits for the
next *new* file, waits until it is complete (same size on two polls and decodable), decodes it
linearly (RAW through :func:`engine.raw.decode_raw`; TIFF, EXR and PNG through
:func:`engine.imageio.read_image`) and returns linear radiance.

Rig name: ``"hotfolder:/path/to/folder"``, e.g.
``devices.open_rig("hotfolder:/data/tether", projector="qtscreen:1", resolution=(4000, 6000),
exposure=1/30, trigger=["gphoto2", "--trigger-capture"])``.
"""

from __future__ import annotations

import os
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from devices.base import Frame
from devices.registry import Availability
from engine.checks import check_positive
from engine.errors import DeviceError, InputError
from engine.imageio import image_info, read_image
from engine.raw import RAW_EXTENSIONS, decode_raw

__all__ = ["HotFolderCamera", "IMAGE_EXTENSIONS", "open_camera", "probe"]

#: non-RAW files the folder may receive (JPEG is display-encoded and lossy: not accepted)
IMAGE_EXTENSIONS = frozenset({".tif", ".tiff", ".exr", ".png"})


def _is_temporary(name: str) -> bool:
    """Names tethering programs use while a file is being written."""
    low = name.lower()
    return low.startswith((".", "~")) or low.endswith((".tmp", ".part", ".partial", ".crdownload", ".download"))


class HotFolderCamera:
    """A camera that delivers each capture as a new file in ``folder``.

    Parameters
    ----------
    folder : str or Path
        The folder the tethering software saves into (must exist). Files present at open are
        ignored; each capture takes the next new file.
    resolution : (H, W), optional
        Expected image size. If omitted, the first capture sets it; every later file must match.
    exposure : float
        Exposure time in seconds the camera is set to (recorded; radiance is divided by it). It
        cannot be changed from here: set it on the camera or in the vendor software.
    gain : float
        Linear gain (ISO / base ISO) the radiance is divided by.
    timeout : float
        Seconds a capture waits for a new complete file before DeviceError.
    poll : float
        Seconds between looks at the folder.
    quiet : float
        A new file that has not changed for this many seconds and still cannot be decoded is
        rejected as unreadable (a writer pausing longer than this would be misread as corrupt).
    trigger : list of str, optional
        Command run (no shell) at the start of each capture to fire the camera, e.g.
        ``["gphoto2", "--trigger-capture"]``; a non-zero exit is a DeviceError. With a trigger,
        a new file that arrives before the camera is fired is refused (the camera fired on its
        own, or twice: that file shows another pattern than the one now projected).
    trigger_timeout : float
        Seconds the trigger command may run.
    extensions : iterable of str, optional
        Accepted file extensions (default: camera RAW formats and ``.tif .tiff .exr .png``);
        other new files (the JPEG of a RAW+JPEG pair) are skipped.
    srgb : bool, optional
        Passed to :func:`engine.imageio.read_image` for TIFF/PNG (``None``: decide by format).
    clock, sleep : callable, optional
        ``time.monotonic`` and ``time.sleep`` replacements (tests); see also :meth:`set_idle`.

    Attributes
    ----------
    last_path : Path or None
        The file the last capture decoded.
    """

    def __init__(
        self,
        folder,
        *,
        resolution=None,
        exposure: float = 1.0,
        gain: float = 1.0,
        timeout: float = 30.0,
        poll: float = 0.2,
        quiet: float = 2.0,
        trigger=None,
        trigger_timeout: float = 30.0,
        extensions=None,
        srgb: bool | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ):
        self.folder = Path(folder).expanduser()
        if not self.folder.is_dir():
            raise DeviceError(f"hot folder {str(self.folder)!r} does not exist or is not a folder")
        if resolution is not None:
            try:
                h, w = (int(v) for v in resolution)
            except (TypeError, ValueError):
                raise InputError(f"resolution must be (H, W), got {resolution!r}") from None
            if h < 1 or w < 1:
                raise InputError(f"resolution must be two positive integers (H, W), got {resolution!r}")
            resolution = (h, w)
        self.resolution: tuple[int, int] | None = resolution
        self._exposure = check_positive("exposure", exposure)
        self.gain = check_positive("gain", gain)
        self.timeout = check_positive("timeout", timeout)
        self.poll = check_positive("poll", poll)
        self.quiet = check_positive("quiet", quiet)
        self.trigger_timeout = check_positive("trigger_timeout", trigger_timeout)
        if trigger is not None:
            if (isinstance(trigger, (str, bytes)) or not all(isinstance(a, (str, os.PathLike)) for a in trigger)
                    or not trigger):
                raise InputError(
                    f"trigger must be a non-empty list of command arguments (run without a shell), got {trigger!r}; "
                    "e.g. ['gphoto2', '--trigger-capture']"
                )
            trigger = [os.fspath(a) for a in trigger]
        self.trigger = trigger
        exts = RAW_EXTENSIONS | IMAGE_EXTENSIONS if extensions is None else {str(e).lower() for e in extensions}
        self.extensions = frozenset(e if e.startswith(".") else "." + e for e in exts)
        self.srgb = srgb
        self._clock, self._sleep = clock, sleep
        self._lock = threading.Lock()
        self._seen = {p.name for p in self._listing()}
        self.last_path: Path | None = None
        self.closed = False

    def set_idle(self, wait: Callable[[float], None]) -> None:
        """Wait between looks at the folder with ``wait(seconds)`` instead of sleeping.

        A rig pairs this with its projector's ``idle`` (:func:`devices.registry.pair`), so a
        projector window stays responsive while the command line waits here on its UI thread.
        """
        self._sleep = wait

    # -- exposure: recorded, not controlled ----------------------------------------------
    @property
    def exposure(self) -> float:
        """Exposure time in seconds the camera is set to (read-only from here)."""
        return self._exposure

    @exposure.setter
    def exposure(self, seconds: float) -> None:
        seconds = check_positive("exposure", seconds)
        if seconds != self._exposure:
            raise InputError(
                "a hot-folder camera's exposure is set on the camera or in its tethering software, not here "
                f"(it is {self._exposure:g} s; asked for {seconds:g} s); "
                "open the rig with exposure= to record a new value"
            )

    # -- the folder ------------------------------------------------------------------------
    def _listing(self) -> list[Path]:
        try:
            return [p for p in self.folder.iterdir() if not _is_temporary(p.name)]
        except OSError as exc:
            raise DeviceError(f"cannot read hot folder {str(self.folder)!r}: {exc}") from None

    def _new_files(self) -> list[Path]:
        fresh = [p for p in self._listing() if p.name not in self._seen and p.is_file()]
        for p in fresh:
            if p.suffix.lower() not in self.extensions:
                self._seen.add(p.name)  # a JPEG preview or a sidecar: not a capture
        fresh = [p for p in fresh if p.suffix.lower() in self.extensions]

        def when(p: Path):
            try:
                return (p.stat().st_mtime_ns, p.name)
            except OSError:
                return (0, p.name)

        return sorted(fresh, key=when)

    def _run_trigger(self) -> None:
        try:
            done = subprocess.run(self.trigger, capture_output=True, text=True, timeout=self.trigger_timeout,
                                  check=False)
        except FileNotFoundError:
            raise DeviceError(f"trigger command {self.trigger[0]!r} not found; install it or fix trigger=") from None
        except subprocess.TimeoutExpired:
            raise DeviceError(f"trigger command {self.trigger} did not finish "
                              f"within {self.trigger_timeout:g} s") from None
        except OSError as exc:
            raise DeviceError(f"trigger command {self.trigger} could not run: {exc}") from None
        if done.returncode != 0:
            tail = (done.stderr or done.stdout or "").strip().splitlines()[-3:]
            raise DeviceError(f"trigger command {self.trigger} failed with exit code {done.returncode}: "
                              f"{' / '.join(tail) or 'no output'}")

    def _decode(self, path: Path):
        """(image (H, W, 3) float32 relative radiance, saturated, black level) or raise."""
        if path.suffix.lower() in RAW_EXTENSIONS:
            raw = decode_raw(path)
            return raw.image, raw.saturated, raw.black_level, {"raw_name": path.name, "white_level": raw.white_level}
        info = image_info(path)
        image = read_image(path, srgb=self.srgb)
        if image.shape[2] == 1:
            image = np.repeat(image, 3, axis=2)
        elif image.shape[2] >= 3:
            image = image[:, :, :3]
        else:
            raise DeviceError(f"{path.name}: expected 1, 3 or 4 channels, got {image.shape[2]}")
        if info.dtype in ("float", "half", "double"):
            saturated = np.zeros(image.shape[:2], bool)  # float files carry no clipping level
        else:
            saturated = np.any(image >= 1.0, axis=2)  # the top code of an integer file
        return np.ascontiguousarray(image, np.float32), saturated, 0.0, {"stored": info.dtype}

    def _wait_complete(self, path: Path, deadline: float):
        """Wait until ``path`` stops growing and decodes; return the decode."""
        last, changed_at, error = None, self._clock(), None
        while True:
            try:
                st = path.stat()
            except OSError as exc:
                raise DeviceError(f"hot-folder file {path.name!r} vanished before it could be read: {exc}") from None
            now = self._clock()
            state = (st.st_size, st.st_mtime_ns)
            if state != last:
                last, changed_at = state, now
            elif st.st_size > 0:  # same size on two polls in a row: try it
                try:
                    return self._decode(path)
                except (DeviceError, InputError, OSError) as exc:
                    error = exc
                    if now - changed_at >= self.quiet:  # unchanged for a while and still bad
                        raise DeviceError(
                            f"hot-folder file {path.name!r} ({st.st_size} bytes, "
                            f"unchanged for {now - changed_at:.1f} s) cannot be read: {exc}"
                        ) from None
            if now >= deadline:
                if error is None or now - changed_at < self.quiet:
                    what = f"was still being written ({st.st_size} bytes so far)"
                else:
                    what = f"cannot be read ({error})"
                raise DeviceError(f"hot-folder file {path.name!r} {what} after the {self.timeout:g} s capture timeout")
            self._sleep(self.poll)

    # -- capturing -------------------------------------------------------------------------
    def capture(self) -> Frame:
        """Fire the trigger (if any), wait for the next new file and decode it.

        Returns
        -------
        Frame
            ``image`` = decoded linear values / (exposure * gain); metadata names the file.

        Raises
        ------
        DeviceError
            No new file within ``timeout``, the file was still being written at the timeout,
            cannot be decoded, or has another size than the camera's; the trigger failed.
        """
        with self._lock:
            if self.closed:
                raise DeviceError(f"hot-folder camera on {str(self.folder)!r} is closed")
            start = self._clock()
            deadline = start + self.timeout
            if self.trigger:
                early = self._new_files()
                if early:
                    self._seen.update(p.name for p in early)
                    names = ", ".join(repr(p.name) for p in early)
                    raise DeviceError(
                        f"hot folder {str(self.folder)!r} received {names} before the camera was triggered: "
                        "a frame taken for an earlier pattern (the camera fired twice, or on its own) "
                        "or written by another program; it is left in the folder and not used: "
                        "check the camera's drive mode, then run again"
                    )
                self._run_trigger()
            while True:
                fresh = self._new_files()
                if fresh:
                    break
                if self._clock() >= deadline:
                    fired = f" after running {self.trigger}" if self.trigger else ""
                    raise DeviceError(
                        f"no new image arrived in hot folder {str(self.folder)!r} within {self.timeout:g} s{fired}; "
                        "is the tethering software saving there, and did the camera fire?"
                    )
                self._sleep(self.poll)
            path = fresh[0]
            self._seen.add(path.name)  # taken, whatever happens next
            image, saturated, black, extra = self._wait_complete(path, deadline)
            h, w = image.shape[:2]
            if self.resolution is None:
                self.resolution = (h, w)
            elif (h, w) != self.resolution:
                eh, ew = self.resolution
                raise DeviceError(f"hot-folder file {path.name!r} is {w}x{h} pixels; the camera's images are {ew}x{eh}")
            self.last_path = path
            scale = np.float32(1.0 / (self._exposure * self.gain))
            meta = {"backend": "hotfolder", "file": path.name, "folder": str(self.folder), **extra}
            return Frame(image=image * scale, exposure=self._exposure, gain=self.gain, black_level=black,
                         saturated=saturated, metadata=meta)

    def close(self) -> None:
        """Stop using the folder (files are left where they are). Idempotent."""
        self.closed = True

    def __repr__(self) -> str:
        return f"HotFolderCamera({str(self.folder)!r}, resolution={self.resolution})"


def open_camera(arg="", **options) -> HotFolderCamera:
    """Open ``"hotfolder:FOLDER"``: a :class:`HotFolderCamera` on the folder (:func:`devices.open_rig`
    pairs it with a projector).

    Raises
    ------
    InputError
        No folder given, or bad options.
    DeviceError
        The folder does not exist.
    """
    if not str(arg):
        raise InputError("hotfolder needs a folder: open_rig('hotfolder:/path/to/folder')")
    return HotFolderCamera(arg, **options)


def probe() -> list[Availability]:
    """The hot folder needs only a folder the tethering software writes to."""
    return [Availability("hotfolder:FOLDER", True, "captures saved into FOLDER by the camera's tethering software")]
