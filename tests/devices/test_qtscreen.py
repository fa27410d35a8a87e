"""The projector window, offscreen: exact pixels, worker-thread show, errors, screen choice."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from engine.errors import DeviceError, InputError

qtscreen = pytest.importorskip("devices.qtscreen")
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def projector():
    events: list = []  # ("settle", seconds, serial painted when the settle wait began)
    holder = {}
    proj = qtscreen.open_projector(0, settle=0.05, timeout=5.0,
                                   sleep=lambda s: events.append(("settle", s, holder["p"].window.painted)))
    holder["p"] = proj
    proj.sleeps = events
    yield proj
    proj.close()
    qtscreen.QApplication.processEvents()


def _pattern(resolution, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, size=(*resolution, 3)).astype(np.float32)


def test_show_paints_exactly_the_quantised_pattern(projector):
    assert projector.resolution == (800, 800)  # Qt's default offscreen screen
    assert projector.bit_depth == 8
    pattern = _pattern(projector.resolution)
    projector.show(pattern)
    expected = np.rint(pattern * 255).astype(np.uint8)
    np.testing.assert_array_equal(projector.grab(), expected)
    np.testing.assert_array_equal(projector.last_shown, expected)
    assert projector.sleeps == [("settle", 0.05, 1)]  # one settle wait per frame, after it was painted
    win = projector.window
    assert win.isFullScreen() and win.windowFlags() & qtscreen.Qt.WindowType.FramelessWindowHint


def test_show_from_a_worker_waits_until_painted(projector):
    pattern = _pattern(projector.resolution, seed=1)
    calls = []
    projector.add_shown_callback(lambda: calls.append(projector.window.painted))
    projector.add_shown_callback(lambda: projector.sleeps.append(("shown", projector.window.painted)))
    result: dict = {}

    def work():
        try:
            projector.show(pattern)
            result["events_at_return"] = list(projector.sleeps)
            result["painted"] = projector.window.painted
            result["serial"] = projector.window.serial
        except BaseException as exc:
            result["error"] = exc

    worker = threading.Thread(target=work)
    worker.start()
    app = qtscreen.QApplication.instance()
    for _ in range(500):  # the UI thread's event loop, bounded
        app.processEvents()
        worker.join(0.01)
        if not worker.is_alive():
            break
    assert not worker.is_alive(), "worker show() never returned"
    assert "error" not in result, result
    # show() returned only after the window had painted this very frame
    assert result["painted"] == result["serial"] == 1 and calls == [1]
    # painted, cameras told, then the settle wait, and only then did show() return
    assert result["events_at_return"] == [("shown", 1), ("settle", 0.05, 1)]
    np.testing.assert_array_equal(projector.grab(), np.rint(pattern * 255).astype(np.uint8))


def test_worker_show_times_out_when_ui_thread_is_blocked():
    proj = qtscreen.open_projector(0, settle=0.0, timeout=0.2)
    try:
        errors = []
        black = np.zeros((*proj.resolution, 3), np.float32)
        worker = threading.Thread(target=lambda: _capture_error(proj.show, black, errors))
        worker.start()
        worker.join(5.0)  # the UI thread does not run its event loop meanwhile
        assert not worker.is_alive()
        assert len(errors) == 1 and isinstance(errors[0], DeviceError)
        assert "did not paint the frame within 0.2 s" in str(errors[0])
    finally:
        proj.close()


def _capture_error(fn, arg, errors):
    try:
        fn(arg)
    except BaseException as exc:
        errors.append(exc)


@pytest.mark.parametrize(
    "image, match",
    [
        (np.zeros((800, 799, 3), np.float32), r"shape \(800, 800, 3\)"),
        (np.zeros((800, 800), np.float32), r"shape \(800, 800, 3\)"),
        (np.zeros((800, 800, 3), np.uint8), "float"),
        (np.full((800, 800, 3), 1.5, np.float32), "in \\[0, 1\\]"),
        (np.full((800, 800, 3), np.nan, np.float32), "finite"),
    ],
)
def test_bad_images_are_refused(projector, image, match):
    with pytest.raises(InputError, match=match):
        projector.show(image)
    assert projector.last_shown is None


def test_identify_pattern_shows_grid_border_and_label(projector):
    projector.identify()
    shown = projector.grab()
    assert tuple(shown[0, 10]) == (255, 0, 0)  # red border
    assert tuple(shown[400, 400]) in {(0, 255, 0), (0, 0, 0), (255, 255, 255)}
    assert tuple(shown[100, 300]) == (255, 255, 255)  # grid line
    plain = qtscreen.identify_pattern(projector.resolution)
    labelled = qtscreen.identify_pattern(projector.resolution, label="offscreen 800x800")
    assert (labelled != plain).any()


def test_unknown_screen_and_closed_projector(projector):
    with pytest.raises(DeviceError, match="there is no screen 5"):
        qtscreen.open_projector(5)
    with pytest.raises(DeviceError, match="no screen named 'HDMI-9'"):
        qtscreen.open_projector("HDMI-9")
    with pytest.raises(DeviceError, match="no second screen"):
        qtscreen.open_projector(None)
    projector.close()
    with pytest.raises(DeviceError, match="closed"):
        projector.show(np.zeros((*projector.resolution, 3), np.float32))


def test_vanished_screen_raises(projector):
    screen = qtscreen.QGuiApplication.screens()[0]
    qtscreen.QApplication.instance().screenRemoved.emit(screen)  # what Qt emits when the projector is unplugged
    with pytest.raises(DeviceError, match="the projector's screen '.*' was disconnected; reconnect the projector"):
        projector.show(np.zeros((*projector.resolution, 3), np.float32))
    with pytest.raises(DeviceError, match="was disconnected"):
        projector.grab_screen()


def test_window_closed_by_the_user_is_a_typed_error_not_a_timeout(projector):
    projector.window.close()  # Alt+F4, or the window manager
    with pytest.raises(DeviceError,
                       match=r"the projector window on '.*' was closed \(by the user or the window manager\)"):
        projector.show(np.zeros((*projector.resolution, 3), np.float32))


def test_idle_keeps_the_ui_thread_serving_a_worker(projector):
    """A camera waiting on the UI thread (the command line's hot folder) must not starve the
    window: a worker's show() and screen grab are served while the UI thread idles."""
    pattern = _pattern(projector.resolution, seed=2)
    result = {}

    def work():
        try:
            projector.show(pattern)
            result["grab"] = projector.grab_screen()
        except BaseException as exc:
            result["error"] = exc

    worker = threading.Thread(target=work)
    worker.start()
    deadline = time.monotonic() + 60  # a loaded machine can take seconds; a starved one never ends
    while worker.is_alive() and time.monotonic() < deadline:
        projector.idle(0.02)
    worker.join(1)
    assert not worker.is_alive(), "the worker's show() was never served"
    assert "error" not in result, result
    np.testing.assert_array_equal(result["grab"], np.rint(pattern * 255).astype(np.uint8))


def test_idle_waits_at_least_the_time_asked(projector):
    start = time.monotonic()
    projector.idle(0.05)
    assert time.monotonic() - start >= 0.05


_CHILD = r"""
import json, sys
import numpy as np
from devices import qtscreen
screens = qtscreen.list_screens()
proj = qtscreen.open_projector(sys.argv[1], settle=0.0)
pattern = np.zeros((*proj.resolution, 3), np.float32)
pattern[:, : proj.resolution[1] // 2, 0] = 1.0
proj.show(pattern)
grab = proj.grab()
ok = bool((grab == np.rint(pattern * 255).astype(np.uint8)).all())
geo = proj.window.geometry()
print(json.dumps({"screens": [list(s)[:4] for s in screens], "name": proj.screen_name,
                  "resolution": list(proj.resolution), "x": geo.x(), "grab_ok": ok}))
proj.close()
"""


@pytest.mark.parametrize("choice", ["1", "PROJ"])
def test_second_screen_selected_by_index_or_name(tmp_path, choice):
    cfg = {
        "screens": [
            {"name": "DESK", "x": 0, "y": 0, "width": 640, "height": 480,
             "logicalDpi": 96, "logicalBaseDpi": 96, "dpr": 1},
            {"name": "PROJ", "x": 640, "y": 0, "width": 320, "height": 200,
             "logicalDpi": 96, "logicalBaseDpi": 96, "dpr": 1},
        ]
    }
    (tmp_path / "cfg.json").write_text(json.dumps(cfg))
    env = dict(os.environ, QT_QPA_PLATFORM=f"offscreen:configfile={tmp_path / 'cfg.json'}", PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", _CHILD, choice], env=env, cwd=ROOT, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["screens"] == [[0, "DESK", 640, 480], [1, "PROJ", 320, 200]]
    assert got["name"] == "PROJ" and got["resolution"] == [200, 320] and got["x"] == 640
    assert got["grab_ok"]


def test_probe_lists_screens():
    entries = qtscreen.probe()
    assert [e.name for e in entries] == ["qtscreen:0"] and entries[0].ok
    assert qtscreen.default_problem() == "no second screen for the projector (1 screen found)"


def test_fingerprint_names_the_screen_a_calibration_belongs_to(projector):
    from devices.base import Rig

    screen = qtscreen.QApplication.screens()[0]
    assert projector.fingerprint == {"screen": screen.name(), "size": list(projector.resolution),
                                     "manufacturer": screen.manufacturer(), "model": screen.model(),
                                     "serial": screen.serialNumber()}

    class _Camera:
        resolution, exposure, gain = (4, 4), 1.0, 1.0

    rig = Rig("opencv:0", _Camera(), projector)
    assert rig.fingerprint["projector screen"] == screen.name()
