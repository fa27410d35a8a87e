"""The qtscreen projector on a real (offscreen) second screen: placement, pixels, repaint, cursor,
screen loss, and the screen listing the wizard shows. Runs on the "desk" and "hidpi" layouts."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import devices
from devices import qtscreen
from engine.errors import DeviceError


@pytest.fixture
def hdmi(layout):
    """The projector screen's configuration and its size in device pixels (Hp, Wp)."""
    (config,) = [s for s in layout["screens"] if s["name"] == "HDMI-1"]
    return config


@pytest.fixture
def dpr(layout):
    return 2.0 if layout["name"] == "hidpi" else 1.0


def _patterns(resolution):
    """Random codes, one-pixel stripes and a checkerboard: any scaling or smoothing changes them."""
    rng = np.random.default_rng(0)
    hp, wp = resolution
    noise = rng.integers(0, 256, (hp, wp, 3)).astype(np.float32) / 255
    stripes = np.zeros((hp, wp, 3), np.float32)
    stripes[:, ::2] = 1.0
    odd = (np.indices((hp, wp)).sum(axis=0) % 2)[..., None]
    checker = (odd * np.array([1.0, 0.5, 0.0], np.float32)).astype(np.float32)
    return [noise, stripes, checker]


def _codes(pattern):
    return np.rint(pattern * 255).astype(np.uint8)


def test_both_screens_are_listed_with_their_sizes(hdmi, dpr):
    screens = qtscreen.list_screens()
    assert [(s.index, s.name, s.width, s.height, s.primary) for s in screens] == [
        (0, "Built-in display", 1920, 1080, True),
        (1, "HDMI-1", hdmi["width"], hdmi["height"], False),
    ]
    assert screens[1].dpr == dpr and str(screens[1]).startswith("1: HDMI-1 1024x768 at (1920, 0)")
    assert [str(a) for a in devices.available_projectors()] == [
        "qtscreen:0: available — Built-in display 1920x1080",
        "qtscreen:1: available — HDMI-1 1024x768",
    ]
    assert qtscreen.default_problem() == ""


@pytest.mark.parametrize("choice", [None, 1, "1", "HDMI-1", "hdmi-1"])
def test_full_screen_on_the_chosen_screen_covering_exactly_its_geometry(choice, hdmi, dpr):
    proj = qtscreen.open_projector(choice, settle=0.0)
    try:
        screen = qtscreen.QGuiApplication.screens()[1]
        win = proj.window
        assert proj.screen_name == "HDMI-1" and win.screen() is screen and win.windowHandle().screen() is screen
        assert win.isFullScreen() and win.isVisible()
        assert win.geometry() == screen.geometry() and win.frameGeometry() == screen.geometry()
        assert screen.geometry().getRect() == (1920, 0, round(hdmi["width"] / dpr), round(hdmi["height"] / dpr))
        assert proj.resolution == (hdmi["height"], hdmi["width"])  # device pixels, what show() takes
        assert win.windowFlags() & qtscreen.Qt.WindowType.FramelessWindowHint
        assert win.windowFlags() & qtscreen.Qt.WindowType.WindowStaysOnTopHint
    finally:
        proj.close()


def test_patterns_are_shown_pixel_for_pixel(layout):
    proj = qtscreen.open_projector("HDMI-1", settle=0.0)
    try:
        for pattern in _patterns(proj.resolution):
            proj.show(pattern)
            np.testing.assert_array_equal(proj.grab(), _codes(pattern))  # no scaling, smoothing or colour management
            if layout["name"] == "desk":
                np.testing.assert_array_equal(proj.grab_screen(), _codes(pattern))  # as displayed
        if layout["name"] == "hidpi":
            # Qt's offscreen platform grabs a window in logical pixels at a ratio of 2: refused, not resampled
            with pytest.raises(DeviceError, match=r"is 512x384 pixels, not its 1024x768 device pixels \(device-pixel"):
                proj.grab_screen()
    finally:
        proj.close()


def test_a_worker_threads_pattern_is_shown_on_the_projector_screen():
    proj = qtscreen.open_projector("HDMI-1", settle=0.0)
    pattern = _patterns(proj.resolution)[0]
    done = threading.Event()
    errors = []

    def work():
        try:
            proj.show(pattern)
        except BaseException as exc:
            errors.append(exc)
        done.set()

    try:
        threading.Thread(target=work).start()
        for _ in range(500):
            proj.idle(0.01)
            if done.is_set():
                break
        assert done.is_set() and errors == []
        np.testing.assert_array_equal(proj.grab(), _codes(pattern))
    finally:
        proj.close()


def test_the_last_pattern_is_kept_on_repaint_and_expose():
    proj = qtscreen.open_projector("HDMI-1", settle=0.0)
    try:
        pattern = _patterns(proj.resolution)[2]
        proj.show(pattern)
        win = proj.window
        win.repaint()
        np.testing.assert_array_equal(proj.grab(), _codes(pattern))
        win.hide()  # covered, minimised or switched away, then exposed again
        win.showFullScreen()
        proj.idle(0.05)
        np.testing.assert_array_equal(proj.grab(), _codes(pattern))
        assert win.geometry() == qtscreen.QGuiApplication.screens()[1].geometry()
    finally:
        proj.close()


def test_the_cursor_is_hidden_over_the_projector():
    proj = qtscreen.open_projector("HDMI-1", settle=0.0)
    try:
        assert proj.window.cursor().shape() == qtscreen.Qt.CursorShape.BlankCursor
    finally:
        proj.close()


def test_the_projector_screen_removed_is_a_typed_error():
    proj = qtscreen.open_projector("HDMI-1", settle=0.0)
    try:
        panel, projector_screen = qtscreen.QGuiApplication.screens()
        app = qtscreen.QApplication.instance()
        app.screenRemoved.emit(panel)  # another screen going away does not matter
        proj.show(np.zeros((*proj.resolution, 3), np.float32))
        app.screenRemoved.emit(projector_screen)  # what Qt emits when HDMI-1 is unplugged
        with pytest.raises(DeviceError, match=r"^the projector's screen 'HDMI-1' was disconnected; reconnect"):
            proj.show(np.zeros((*proj.resolution, 3), np.float32))
    finally:
        proj.close()
