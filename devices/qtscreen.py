"""The projector as a screen: a frameless, stay-on-top, full-screen window on a chosen QScreen.

The only module in ``devices/`` that imports Qt, because a projector *is* a screen. The window
lives on the Qt UI thread. :meth:`QtScreenProjector.show` may be called from that thread or from
a worker: a worker's frame is handed to the UI thread by a queued signal, and ``show`` returns
only after the window has painted it and the settle time (projector input lag) has passed.

Examples
--------
A projector on the second screen, driven from an acquisition worker::

    from devices.qtscreen import list_screens, open_projector
    print(*list_screens(), sep="\\n")       # index, name, resolution of every screen
    projector = open_projector("HDMI-1", settle=0.15)   # on the UI thread
    projector.identify()                   # name, resolution and a grid, to check the wiring
    projector.show(pattern)                # from any thread; returns once the frame is up

Over 500 lines on purpose: the projector window, the screen list (with EDID identity) and the
cross-thread hand-off of patterns are one Qt object's life cycle.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from PySide6.QtCore import QCoreApplication, QEventLoop, QPoint, QRect, Qt, QThread, QTimer, Signal, Slot
from PySide6.QtGui import QColor, QFont, QGuiApplication, QImage, QPainter
from PySide6.QtWidgets import QApplication, QWidget

from devices.registry import Availability
from engine.errors import DeviceError, InputError

__all__ = [
    "QtScreenProjector",
    "ScreenInfo",
    "default_problem",
    "identify_pattern",
    "list_screens",
    "open_projector",
    "probe",
]


class ScreenInfo(NamedTuple):
    """One screen as Qt sees it; ``width``/``height`` in device pixels (what a projector shows)."""

    # mypy reads a field named "index" as an incompatible override of the tuple method index();
    # that method is not used on a ScreenInfo, and the field name is public API
    index: int  # type: ignore[assignment]
    name: str
    width: int
    height: int
    x: int
    y: int
    dpr: float
    primary: bool

    def __str__(self) -> str:
        primary = " (primary)" if self.primary else ""
        return f"{self.index}: {self.name} {self.width}x{self.height} at ({self.x}, {self.y}){primary}"


def _display_available() -> bool:
    """Whether creating a QApplication can succeed (Qt aborts the process when it cannot)."""
    if os.environ.get("QT_QPA_PLATFORM"):
        return True
    if sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def _application() -> QApplication:
    """The running QApplication, created on the main thread if there is none."""
    app = QCoreApplication.instance()
    if app is None:
        if threading.current_thread() is not threading.main_thread():
            raise DeviceError("no Qt application is running and one can only be created on the main thread")
        if not _display_available():
            raise DeviceError("no display: set DISPLAY/WAYLAND_DISPLAY, or QT_QPA_PLATFORM=offscreen for tests")
        app = QApplication([sys.argv[0] if sys.argv else "albedit"])
    if not isinstance(app, QApplication):
        raise DeviceError(f"a {type(app).__name__} is running; the projector window needs a QApplication (widgets)")
    return app


def _on_ui_thread() -> bool:
    app = QCoreApplication.instance()
    return app is not None and QThread.currentThread() is app.thread()


def _device_size(screen) -> tuple[int, int]:
    geom, dpr = screen.geometry(), screen.devicePixelRatio()
    return round(geom.height() * dpr), round(geom.width() * dpr)


def list_screens() -> list[ScreenInfo]:
    """List the screens Qt knows, with their resolutions in device pixels.

    Returns
    -------
    list of ScreenInfo
        In Qt's order; the index is what ``open_projector(screen=index)`` takes.

    Raises
    ------
    DeviceError
        No display, or no QApplication and not on the main thread.
    """
    _application()
    primary = QGuiApplication.primaryScreen()
    out = []
    for i, s in enumerate(QGuiApplication.screens()):
        h, w = _device_size(s)
        g = s.geometry()
        out.append(ScreenInfo(i, s.name(), w, h, g.x(), g.y(), float(s.devicePixelRatio()), s is primary))
    return out


def _find_screen(screen: int | str):
    screens = QGuiApplication.screens()
    listing = "; ".join(str(s) for s in list_screens()) or "none"
    if isinstance(screen, str) and screen.strip().lstrip("-").isdigit():
        screen = int(screen)
    if isinstance(screen, (int, np.integer)) and not isinstance(screen, bool):
        if not 0 <= screen < len(screens):
            raise DeviceError(f"there is no screen {screen}: {len(screens)} screen(s) found ({listing})")
        return screens[int(screen)]
    if isinstance(screen, str):
        for s in screens:
            if s.name() == screen:
                return s
        for s in screens:
            if s.name().lower() == screen.lower():
                return s
        raise DeviceError(f"there is no screen named {screen!r}; screens: {listing}")
    raise InputError(f"screen must be a screen index or name, got {screen!r}")


def _rgb_array(image: QImage) -> np.ndarray:
    """Copy a QImage into an (H, W, 3) uint8 RGB array."""
    img = image.convertToFormat(QImage.Format.Format_RGB888)
    h, w, stride = img.height(), img.width(), img.bytesPerLine()
    buf = np.frombuffer(img.constBits(), np.uint8, count=h * stride).reshape(h, stride)
    return buf[:, : 3 * w].reshape(h, w, 3).copy()


def identify_pattern(resolution: tuple[int, int], *, label: str = "", spacing: int = 100) -> np.ndarray:
    """A pattern to check a projector: a grid, a border, a centre cross and a text label.

    Parameters
    ----------
    resolution : (Hp, Wp)
        Projector pixels.
    label : str
        Text drawn in the middle (the screen's name and resolution, say).
    spacing : int
        Grid spacing in projector pixels.

    Returns
    -------
    (Hp, Wp, 3) float32 in [0, 1]
        White grid lines every ``spacing`` pixels on black, a red 2-pixel border, a green cross
        through the centre, the label in white.
    """
    hp, wp = (int(v) for v in resolution)
    if hp < 1 or wp < 1 or spacing < 1:
        raise InputError(f"resolution must be two positive integers and spacing >= 1, got {resolution}, {spacing}")
    img = np.zeros((hp, wp, 3), np.float32)
    img[::spacing, :, :] = 1.0
    img[:, ::spacing, :] = 1.0
    img[hp // 2, :, :] = (0.0, 1.0, 0.0)
    img[:, wp // 2, :] = (0.0, 1.0, 0.0)
    border = np.zeros((hp, wp), bool)
    border[:2, :] = border[-2:, :] = border[:, :2] = border[:, -2:] = True
    img[border] = (1.0, 0.0, 0.0)
    if label:
        _application()
        text = QImage(wp, hp, QImage.Format.Format_RGB888)
        text.fill(QColor(0, 0, 0))
        painter = QPainter(text)
        font = QFont()
        font.setPixelSize(max(8, hp // 20))
        painter.setFont(font)
        painter.setPen(QColor(255, 255, 255))
        flags = int(Qt.AlignmentFlag.AlignCenter)
        box = painter.boundingRect(QRect(0, 0, wp, hp), flags, label).adjusted(-4, -4, 4, 4)
        painter.drawText(QRect(0, 0, wp, hp), flags, label)
        painter.end()
        ink = _rgb_array(text).astype(np.float32) / 255.0
        y0, y1 = max(box.top(), 0), min(box.bottom() + 1, hp)
        x0, x1 = max(box.left(), 0), min(box.right() + 1, wp)
        img[y0:y1, x0:x1] = 0.0  # a black plate behind the label keeps it legible
        img = np.maximum(img, ink)
    return img


class _ProjectorWindow(QWidget):
    """The full-screen window; every method runs on the UI thread."""

    present_requested = Signal()
    close_requested = Signal()
    call_requested = Signal()

    def __init__(self) -> None:
        flags = Qt.WindowType.Window | Qt.WindowType.FramelessWindowHint | Qt.WindowType.WindowStaysOnTopHint
        super().__init__(None, flags)
        self.setWindowTitle("Albedit projector")
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent)
        self.setCursor(Qt.CursorShape.BlankCursor)
        self.image: QImage | None = None
        self.serial = 0  # serial of the image set last
        self.painted = 0  # serial of the image painted last
        self._lock = threading.Lock()
        self._pending: tuple[int, QImage, threading.Event] | None = None
        self._deferred: tuple[int, threading.Event] | None = None
        self._calls: list[tuple[Callable[[], object], dict, threading.Event]] = []
        self.closing = False  # set by the projector before it closes the window itself
        self.on_closed: Callable[[], None] | None = None
        self.present_requested.connect(self._present_pending, Qt.ConnectionType.QueuedConnection)
        self.close_requested.connect(self._close_now, Qt.ConnectionType.QueuedConnection)
        self.call_requested.connect(self._run_calls, Qt.ConnectionType.QueuedConnection)

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        if not self.closing and self.on_closed is not None:
            self.on_closed()  # closed by the user or the window manager, not by the projector
        super().closeEvent(event)

    def paintEvent(self, event) -> None:  # noqa: N802 (Qt name)
        painter = QPainter(self)
        if self.image is None:
            painter.fillRect(self.rect(), QColor(0, 0, 0))
        else:
            painter.drawImage(QPoint(0, 0), self.image)
        painter.end()
        self.painted = self.serial
        if self._deferred is not None and self._deferred[0] == self.painted:
            self._deferred[1].set()
            self._deferred = None

    def present(self, serial: int, image: QImage, done: threading.Event) -> None:
        """Set the image and repaint now; ``done`` is set once it has been painted."""
        self.image, self.serial = image, serial
        self.repaint()
        if self.painted == serial:
            done.set()
        else:  # not exposed yet: the next paintEvent sets it
            self._deferred = (serial, done)
            self.update()

    def post(self, serial: int, image: QImage, done: threading.Event) -> None:
        """From a worker thread: queue the frame for the UI thread."""
        with self._lock:
            self._pending = (serial, image, done)
        self.present_requested.emit()

    def request_call(self, fn: Callable[[], object], box: dict, done: threading.Event) -> None:
        """From a worker thread: run ``fn()`` on the UI thread, its result or error into ``box``."""
        with self._lock:
            self._calls.append((fn, box, done))
        self.call_requested.emit()

    def wake_waiters(self) -> None:
        """Release any show() or call waiting for the UI thread (its caller then checks why)."""
        with self._lock:
            pending, self._pending = self._pending, None
            calls, self._calls = self._calls, []
        deferred, self._deferred = self._deferred, None
        for item in (pending, deferred, *calls):
            if item is not None:
                item[-1].set()

    @Slot()
    def _run_calls(self) -> None:
        with self._lock:
            calls, self._calls = self._calls, []
        for fn, box, done in calls:
            try:
                box["value"] = fn()
            except Exception as exc:  # noqa: BLE001 - handed to the waiting thread, never out of the slot
                box["error"] = exc
            finally:
                done.set()

    @Slot()
    def _present_pending(self) -> None:
        with self._lock:
            pending, self._pending = self._pending, None
        if pending is not None:
            self.present(*pending)

    @Slot()
    def _close_now(self) -> None:
        self.closing = True
        self.close()
        self.deleteLater()


class QtScreenProjector:
    """A projector that is a full-screen window on one screen.

    Parameters
    ----------
    screen : int or str
        Screen index (see :func:`list_screens`) or name (``"HDMI-1"``).
    settle : float
        Seconds to wait after the frame is painted, for the projector's input lag (measure it:
        project black then white and capture at increasing delays).
    timeout : float
        Seconds to wait for the UI thread to paint a frame before raising DeviceError.
    sleep : callable, optional
        ``sleep(seconds)`` used for the settle wait (default :meth:`idle`; tests record it).

    Attributes
    ----------
    resolution : (Hp, Wp)
        The screen's size in device pixels; ``show`` takes exactly this shape.
    bit_depth : int
        8: frames are quantised as ``round(x * 255)``.
    screen_name : str
    last_shown : (Hp, Wp, 3) uint8 or None
        The codes of the last frame shown.

    Raises
    ------
    DeviceError
        No display, unknown screen, or not created on the Qt UI thread.
    """

    bit_depth = 8

    def __init__(self, screen: int | str = 1, *, settle: float = 0.1, timeout: float = 5.0,
                 sleep: Callable[[float], None] | None = None):
        app = _application()
        if not _on_ui_thread():
            raise DeviceError("open the projector on the Qt UI thread (the thread that created the QApplication)")
        settle, timeout = float(settle), float(timeout)
        if not (np.isfinite(settle) and settle >= 0):
            raise InputError(f"settle must be a non-negative number of seconds, got {settle!r}")
        if not (np.isfinite(timeout) and timeout > 0):
            raise InputError(f"timeout must be a positive number of seconds, got {timeout!r}")
        qscreen = _find_screen(screen)
        self.screen_name = qscreen.name()
        self.resolution = _device_size(qscreen)
        self.settle, self.timeout = settle, timeout
        self._sleep = self.idle if sleep is None else sleep
        self._qscreen = qscreen
        #: what a calibration depends on (engine.rig.RigLike.fingerprint): the screen and, where its
        #: EDID reports them, the projector's maker, model and serial number
        self.fingerprint = {"screen": self.screen_name, "size": [int(v) for v in self.resolution],
                            "manufacturer": qscreen.manufacturer(), "model": qscreen.model(),
                            "serial": qscreen.serialNumber()}
        self._dpr = float(qscreen.devicePixelRatio())
        self._lost: str | None = None
        self._callbacks: list[Callable[[], None]] = []
        self._show_lock = threading.Lock()
        self._serial = 0
        self.last_shown: np.ndarray | None = None
        self.closed = False
        self.window = _ProjectorWindow()
        self.window.on_closed = self._on_window_closed
        self.window.setScreen(qscreen)  # right before showFullScreen: Wayland ignores later moves
        self.window.setGeometry(qscreen.geometry())
        self.window.showFullScreen()
        app.screenRemoved.connect(self._on_screen_removed)
        app.processEvents()

    # -- events -------------------------------------------------------------------------
    def _on_screen_removed(self, screen) -> None:
        if screen is not None and screen.name() == self.screen_name:
            self._lost = (
                f"the projector's screen {self.screen_name!r} was disconnected; "
                "reconnect the projector and open the rig again"
            )
            self.window.wake_waiters()  # a show() waiting for a paint fails now, not at its timeout

    def _on_window_closed(self) -> None:
        self._lost = (
            f"the projector window on {self.screen_name!r} was closed (by the user or the window manager) "
            "while the rig was open; open the rig again (captures taken so far are kept)"
        )
        self.window.wake_waiters()

    def idle(self, seconds: float) -> None:
        """Wait ``seconds``; on the UI thread, keep processing its events meanwhile.

        A projector window whose thread sleeps cannot repaint and is reported "not responding"
        by desktop shells after a few seconds; cameras that wait on the UI thread (a hot
        folder polled by the command line) wait through this instead (see
        :func:`devices.registry.pair`).
        """
        seconds = float(seconds)
        if seconds <= 0:
            return
        if not _on_ui_thread():
            time.sleep(seconds)
            return
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            loop, timer = QEventLoop(), QTimer()
            timer.setSingleShot(True)
            timer.setTimerType(Qt.TimerType.PreciseTimer)
            timer.timeout.connect(loop.quit)
            timer.start(max(1, int(np.ceil(left * 1000))))
            loop.exec()
            timer.stop()

    def add_shown_callback(self, callback: Callable[[], None]) -> None:
        """Call ``callback()`` after each new frame is painted (before the settle wait).

        Cameras use it to drop frames queued before the pattern changed.
        """
        self._callbacks.append(callback)

    # -- showing ------------------------------------------------------------------------
    def _quantise(self, image) -> np.ndarray:
        a = np.asarray(image)
        hp, wp = self.resolution
        if a.shape != (hp, wp, 3):
            raise InputError(
                f"projector image must have shape {(hp, wp, 3)} (the resolution of screen "
                f"{self.screen_name!r}), got {a.shape}"
            )
        if a.dtype.kind != "f":
            raise InputError(f"projector image must be float in [0, 1], got dtype {a.dtype}")
        lo, hi = float(np.min(a)), float(np.max(a))
        if not (np.isfinite(lo) and np.isfinite(hi)) or lo < 0.0 or hi > 1.0:
            raise InputError(
                f"projector image values must be finite and in [0, 1] (after the inverse response), "
                f"got min {lo:g}, max {hi:g}"
            )
        return np.rint(a * 255.0).astype(np.uint8)

    def show(self, image: np.ndarray) -> None:
        """Display ``image`` and return once it is painted and the settle time has passed.

        Parameters
        ----------
        image : (Hp, Wp, 3) float in [0, 1]
            Projector pixels, already passed through the inverse response; quantised to 8 bits.

        Raises
        ------
        InputError
            Wrong shape, not float, or values outside [0, 1].
        DeviceError
            The screen was disconnected, the projector is closed, or the UI thread did not
            paint the frame within ``timeout`` seconds.

        Notes
        -----
        Safe to call from any thread. From a worker, the frame is queued to the UI thread
        (whose event loop must be running) and this call blocks until it is painted.
        """
        codes = self._quantise(image)
        if self._lost:
            raise DeviceError(self._lost)
        if self.closed:
            raise DeviceError(f"the projector on screen {self.screen_name!r} is closed")
        hp, wp = self.resolution
        qimage = QImage(codes.data, wp, hp, 3 * wp, QImage.Format.Format_RGB888).copy()
        qimage.setDevicePixelRatio(self._dpr)
        with self._show_lock:
            self._serial += 1
            done = threading.Event()
            if _on_ui_thread():
                self.window.present(self._serial, qimage, done)
                deadline = time.monotonic() + self.timeout
                while not done.is_set() and time.monotonic() < deadline:
                    QCoreApplication.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 50)
            else:
                self.window.post(self._serial, qimage, done)
                done.wait(self.timeout)
            if self._lost:
                raise DeviceError(self._lost)
            if not done.is_set():
                raise DeviceError(
                    f"the projector window on {self.screen_name!r} did not paint the frame within "
                    f"{self.timeout:g} s; is the window hidden or closed, or the Qt event loop blocked?"
                )
            self.last_shown = codes
            for callback in self._callbacks:
                callback()
            if self.settle > 0:
                self._sleep(self.settle)

    def identify(self) -> None:
        """Show the screen's name, resolution and a grid (:func:`identify_pattern`)."""
        hp, wp = self.resolution
        self.show(identify_pattern(self.resolution, label=f"{self.screen_name}  {wp}x{hp}"))

    def grab(self) -> np.ndarray:
        """What the window paints now, as (Hp, Wp, 3) uint8 (UI thread only; for checks and tests)."""
        if not _on_ui_thread():
            raise DeviceError("grab() must be called on the Qt UI thread")
        return _rgb_array(self.window.grab().toImage())

    def grab_screen(self) -> np.ndarray:
        """What the projector's screen displays now, as (Hp, Wp, 3) uint8; from any thread.

        This is what a camera looking at the screen sees: the window's content as the platform
        displays it (its backing store, not a fresh paint) where the window is, black where it
        does not cover the screen. From a worker thread the grab runs on the UI thread (whose
        event loop must be running, or which must be waiting in :meth:`idle`).

        Raises
        ------
        DeviceError
            The screen was disconnected or the window closed, the UI thread did not answer
            within ``timeout``, or the platform's grab is not in device pixels (Qt's offscreen
            platform at a device-pixel ratio other than 1).

        Notes
        -----
        The window is grabbed by its id: Qt's offscreen platform grabs a whole screen
        (``grabWindow(0)``) from the origin of the desktop rather than of that screen, which
        gives an uninitialised picture for a screen that is not at (0, 0).
        """
        if self._lost:
            raise DeviceError(self._lost)
        return self.call_on_ui(self._grab_screen_now, what=f"grab screen {self.screen_name!r}")

    def _grab_screen_now(self) -> np.ndarray:
        if self._lost:
            raise DeviceError(self._lost)
        pixmap = self._qscreen.grabWindow(self.window.winId())
        content = _rgb_array(pixmap.toImage())
        win, scr = self.window.geometry(), self._qscreen.geometry()
        expected = (round(win.height() * self._dpr), round(win.width() * self._dpr))
        if content.shape[:2] != expected:
            raise DeviceError(
                f"the grab of the projector window on {self.screen_name!r} is {content.shape[1]}x{content.shape[0]} "
                f"pixels, not its {expected[1]}x{expected[0]} device pixels (device-pixel ratio {self._dpr:g})"
            )
        hp, wp = self.resolution
        screen = np.zeros((hp, wp, 3), np.uint8)
        y0, x0 = round((win.y() - scr.y()) * self._dpr), round((win.x() - scr.x()) * self._dpr)
        ys, xs = slice(max(y0, 0), min(y0 + expected[0], hp)), slice(max(x0, 0), min(x0 + expected[1], wp))
        if ys.start < ys.stop and xs.start < xs.stop:
            screen[ys, xs] = content[ys.start - y0 : ys.stop - y0, xs.start - x0 : xs.stop - x0]
        return screen

    def call_on_ui(self, fn: Callable[[], object], *, what: str = "answer"):
        """Run ``fn()`` on the UI thread (directly when called there) and return its result.

        Raises
        ------
        DeviceError
            The UI thread did not run it within ``timeout`` (its event loop is blocked), or the
            screen was lost meanwhile; ``fn``'s own exceptions propagate.
        """
        if _on_ui_thread():
            return fn()
        box: dict = {}
        done = threading.Event()
        self.window.request_call(fn, box, done)
        if not done.wait(self.timeout):
            raise DeviceError(f"the UI thread did not {what} within {self.timeout:g} s; is its event loop blocked?")
        if "error" in box:
            raise box["error"]
        if "value" not in box:  # woken without running: the screen or window is gone
            raise DeviceError(self._lost or f"the UI thread did not {what}")
        return box["value"]

    def close(self) -> None:
        """Close the window. Idempotent; safe from any thread."""
        if self.closed:
            return
        self.closed = True
        self.window.closing = True
        app = QCoreApplication.instance()
        if isinstance(app, QGuiApplication):  # the projector was opened with one (_application)
            try:
                app.screenRemoved.disconnect(self._on_screen_removed)
            except (RuntimeError, TypeError):
                pass
        if _on_ui_thread():
            self.window.close()
            self.window.deleteLater()
        else:
            self.window.close_requested.emit()

    def __repr__(self) -> str:
        return f"QtScreenProjector({self.screen_name!r}, resolution={self.resolution}, settle={self.settle:g})"


def open_projector(screen: int | str | None = None, *, settle: float = 0.1, timeout: float = 5.0,
                   sleep=None) -> QtScreenProjector:
    """Open a full-screen projector window (on the Qt UI thread).

    Parameters
    ----------
    screen : int, str or None
        Screen index or name; ``None`` means the second screen (index 1).
    settle, timeout, sleep
        See :class:`QtScreenProjector`.

    Returns
    -------
    QtScreenProjector

    Raises
    ------
    DeviceError
        ``screen`` is None and there is only one screen, or the screen does not exist.
    """
    if screen is None:
        _application()
        n = len(QGuiApplication.screens())
        if n < 2:
            raise DeviceError(
                f"no second screen for the projector ({n} screen found); connect the projector as a "
                "second display, or pass projector='qtscreen:0' to project on the only screen"
            )
        screen = 1
    return QtScreenProjector(screen, settle=settle, timeout=timeout, sleep=sleep)


def default_problem() -> str:
    """Why the default projector (a window on the second screen) cannot open here, or ``""`` if it can."""
    try:
        _application()
    except DeviceError as exc:
        return str(exc)
    n = len(QGuiApplication.screens())
    return "" if n >= 2 else f"no second screen for the projector ({n} screen found)"


def probe() -> list[Availability]:
    """One entry per screen a projector window can open on (``"qtscreen:INDEX"``)."""
    try:
        screens = list_screens()
    except DeviceError as exc:
        return [Availability("qtscreen:", False, str(exc))]
    if not screens:
        return [Availability("qtscreen:", False, "no screen found")]
    return [Availability(f"qtscreen:{s.index}", True, f"{s.name or 'unnamed screen'} {s.width}x{s.height}")
            for s in screens]
