"""The gphoto2 backend on the real python-gphoto2: no camera, a camera that is not there, hung
calls, and libgphoto2's own virtual camera (a Nikon D750 over PTP that python-gphoto2's wheels
ship for testing), each ending in the typed error and one-line message the CLI prints.

Skipped when python-gphoto2 is not installed (``.ci/run`` runs the device tests both ways).
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

gp = pytest.importorskip("gphoto2")

from app.main import main  # noqa: E402
from devices.gphoto2_camera import GPhoto2Camera, list_cameras, probe  # noqa: E402
from engine.errors import DeviceError  # noqa: E402

VUSB = Path(gp.__file__).parent / "libgphoto2" / "vusb"


@pytest.fixture
def no_camera():
    """The real USB drivers; skipped on a machine that has a camera plugged in."""
    if list_cameras():
        pytest.skip("a camera is connected to this machine")


@pytest.fixture(scope="session")
def vcamera_files(tmp_path_factory):
    """The folder the virtual camera serves (libgphoto2 reads it once per process)."""
    import cv2

    folder = tmp_path_factory.mktemp("vcamera")
    assert cv2.imwrite(str(folder / "frame.jpg"), np.full((8, 8, 3), 128, np.uint8))
    return folder


@pytest.fixture
def vcamera(monkeypatch, vcamera_files):
    """libgphoto2's virtual USB camera instead of the real USB drivers, for this test."""
    if not VUSB.is_dir():
        pytest.skip("this python-gphoto2 build has no virtual camera")
    monkeypatch.setenv("IOLIBS", str(VUSB))
    monkeypatch.setenv("VCAMERADIR", str(vcamera_files))
    return "Nikon DSC D750"


def _cli_error(capsys, *argv) -> str:
    assert main(list(argv)) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err  # one line, no traceback
    return err[0]


def test_detection_with_no_camera(no_camera, capsys):
    (entry,) = probe()
    assert entry.name == "gphoto2" and not entry.ok and entry.reason.startswith("no camera detected")
    with pytest.raises(DeviceError, match="opening the camera failed: no camera found: check that it is connected"):
        GPhoto2Camera()
    line = _cli_error(capsys, "devices", "--check", "gphoto2")
    assert line.startswith("albedit devices: error: opening the camera failed: no camera found")


def test_opening_a_camera_that_is_not_there(no_camera):
    with pytest.raises(DeviceError, match=r"^no camera 'Canon EOS 5D' found; cameras found: none$"):
        GPhoto2Camera("Canon EOS 5D")
    with pytest.raises(DeviceError, match=r"^opening the camera at usb:009,009 failed: no camera found"):
        GPhoto2Camera("usb:009,009")


def test_virtual_camera_is_detected_and_opened_by_model_and_port(vcamera):
    ((model, port),) = list_cameras()
    assert model == vcamera and port.startswith("usb:")
    assert [str(a) for a in probe()] == [f"gphoto2:{port}: available — {vcamera}"]
    for name in (vcamera, port):
        cam = GPhoto2Camera(name, image_format=None, release_after=None)
        try:
            assert cam.connected and cam.settings["capture_target"] == "Internal RAM"
            assert cam.warnings == ["the camera has no ISO setting: gain recorded as 1"]
        finally:
            cam.close()


def test_virtual_camera_without_a_raw_setting_is_a_plain_error(vcamera, capsys):
    with pytest.raises(DeviceError, match=r"the camera has no image format setting \(tried imageformat, imagequality"):
        GPhoto2Camera()
    line = _cli_error(capsys, "devices", "--check", "gphoto2")
    assert line == ("albedit devices: error: the camera has no image format setting "
                    "(tried imageformat, imagequality, raw, recordingmedia)")


def test_virtual_camera_shutter_speeds_capture_and_reconnection(vcamera):
    cam = GPhoto2Camera(image_format=None, release_after=None)
    try:
        # the driver's "0.0100s" style choices are parsed; exposure snaps to the nearest one
        assert [text for _, text in cam._shutters][:3] == ["0.0001s", "0.0012s", "0.0025s"]
        cam.exposure = 1 / 30
        assert cam.exposure == 0.05 and cam.settings["exposure"] == "0.0500s"
        # it delivers a JPEG: refused in plain words, and deleted off the camera all the same
        with pytest.raises(DeviceError, match=r"the camera delivered 'GPH_\d{4}.JPG', not a RAW file; set"):
            cam.capture()
        assert not any("deleting" in w for w in cam.warnings)
        cam.release()
        assert not cam.connected
        # the next capture opens a fresh session (libgphoto2 cannot re-init a handle after exit)
        with pytest.raises(DeviceError, match="not a RAW file"):
            cam.capture()
        assert cam.connected and cam.settings["exposure"] == "0.0500s"
    finally:
        cam.close()


def test_a_call_stuck_in_libgphoto2_times_out_and_the_camera_recovers(vcamera):
    """A capture that never returns (a camera that stopped answering) is held inside libgphoto2
    itself: its log callback, which the library calls from the capturing thread, blocks."""
    cam = GPhoto2Camera(image_format=None, release_after=None, timeout=0.5)
    gate, held = threading.Event(), threading.Event()

    def log(level, domain, message, data=None):
        if threading.current_thread().name == "albedit-capturing" and not gate.is_set():
            held.set()
            gate.wait(30)

    handle = gp.gp_log_add_func(gp.GP_LOG_DEBUG, log)
    try:
        with pytest.raises(DeviceError, match=r"did not finish capturing within 0.5\d* s; check the cable"):
            cam.capture()
        assert held.is_set()
        with pytest.raises(DeviceError, match="has not answered an earlier capturing yet; unplug and reconnect it"):
            cam.capture()
        gate.set()
        cam._dog._hung.join(10)
        # the abandoned call came back: a fresh session, and the camera answers again
        with pytest.raises(DeviceError, match="not a RAW file"):
            cam.capture()
    finally:
        gate.set()
        del handle
        cam.close()

