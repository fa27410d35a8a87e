"""The hot-folder camera with files written by another thread: slow, corrupt, wrong size, late."""

from __future__ import annotations

import sys
import threading
import time

import numpy as np
import pytest

import devices
from devices.hotfolder import HotFolderCamera
from engine.errors import DeviceError, InputError
from engine.imageio import write_image

H, W = 32, 48
FAST = dict(poll=0.01, quiet=0.3, timeout=5.0)


def _writer(target, payload: bytes, *, chunks=1, pause=0.0, delay=0.05):
    """Write ``payload`` to ``target`` from another thread in ``chunks`` pieces."""

    def run():
        time.sleep(delay)
        step = -(-len(payload) // chunks)
        with open(target, "wb") as fh:
            for i in range(0, len(payload), step):
                fh.write(payload[i : i + step])
                fh.flush()
                time.sleep(pause)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def _tiff_bytes(tmp_path, image, dtype="uint16"):
    scratch = tmp_path.parent / (tmp_path.name + "_scratch")
    scratch.mkdir(exist_ok=True)
    path = write_image(scratch / "x.tif", image, dtype=dtype)
    return path.read_bytes()


def test_raw_file_written_slowly_is_decoded_linearly(tmp_path, make_dng):
    (tmp_path / "old.dng").write_bytes(make_dng(np.full((H, W), 500, np.uint16)))  # present at open: ignored
    cam = HotFolderCamera(tmp_path, exposure=0.5, gain=2.0, **FAST)
    mosaic = np.full((H, W), 64 + 1000, np.uint16)
    mosaic[:2, :2] = 4000  # clipped photosites
    writer = _writer(tmp_path / "IMG_0001.dng", make_dng(mosaic), chunks=8, pause=0.03)
    frame = cam.capture()
    writer.join(5)
    expected = 1000 / (4000 - 64) / (0.5 * 2.0)
    np.testing.assert_allclose(frame.image[8:, 8:], expected, rtol=1e-4)
    assert frame.image.dtype == np.float32 and frame.image.shape == (H, W, 3)
    assert frame.saturated[0, 0] and not frame.saturated[8:, 8:].any()
    assert frame.black_level == 64.0 and frame.metadata["raw_name"] == "IMG_0001.dng"
    assert cam.resolution == (H, W) and cam.last_path.name == "IMG_0001.dng"


def test_captures_take_files_in_arrival_order_and_skip_jpeg(tmp_path):
    cam = HotFolderCamera(tmp_path, resolution=(H, W), **FAST)
    a = np.full((H, W, 3), 0.25, np.float32)
    b = np.full((H, W, 3), 0.5, np.float32)
    write_image(tmp_path / "a.exr", a)
    (tmp_path / "a.jpg").write_bytes(b"\xff\xd8 preview")
    time.sleep(0.02)
    write_image(tmp_path / "b.exr", b)
    first, second = cam.capture(), cam.capture()
    assert (first.metadata["file"], second.metadata["file"]) == ("a.exr", "b.exr")
    np.testing.assert_allclose(first.image, 0.25)
    np.testing.assert_allclose(second.image, 0.5)
    assert not first.saturated.any()


def test_integer_tiff_top_code_is_saturated(tmp_path):
    cam = HotFolderCamera(tmp_path, **FAST)
    image = np.full((H, W, 3), 0.5, np.float32)
    image[3, 4, 1] = 1.0
    _writer(tmp_path / "shot.tif", _tiff_bytes(tmp_path, image), chunks=3, pause=0.02)
    frame = cam.capture()
    np.testing.assert_allclose(frame.image[0, 0], 0.5, atol=1e-4)
    assert frame.saturated.sum() == 1 and frame.saturated[3, 4]


def test_corrupt_file_is_rejected_by_name(tmp_path, make_dng):
    cam = HotFolderCamera(tmp_path, **FAST)
    (tmp_path / "IMG_0002.dng").write_bytes(make_dng(np.zeros((H, W), np.uint16))[:200])
    with pytest.raises(DeviceError, match=r"'IMG_0002.dng' \(200 bytes, unchanged for .* cannot be read"):
        cam.capture()


def test_wrong_size_is_rejected_with_both_sizes(tmp_path):
    cam = HotFolderCamera(tmp_path, resolution=(H, W), **FAST)
    write_image(tmp_path / "small.exr", np.zeros((H, W - 8, 3), np.float32))
    with pytest.raises(DeviceError, match=r"'small.exr' is 40x32 pixels; the camera's images are 48x32"):
        cam.capture()


def test_no_file_times_out(tmp_path):
    cam = HotFolderCamera(tmp_path, poll=0.01, timeout=0.2)
    with pytest.raises(DeviceError, match=r"no new image arrived .* within 0.2 s"):
        cam.capture()


def test_file_still_being_written_at_the_timeout(tmp_path, make_dng):
    cam = HotFolderCamera(tmp_path, poll=0.01, quiet=5.0, timeout=0.4)
    writer = _writer(tmp_path / "IMG_0003.dng", make_dng(np.zeros((H, W), np.uint16)), chunks=40, pause=0.05, delay=0.0)
    with pytest.raises(DeviceError, match=r"'IMG_0003.dng' was still being written .* after the 0.4 s capture timeout"):
        cam.capture()
    writer.join(5)


def test_trigger_command_runs_without_shell(tmp_path):
    script = (
        "import sys, numpy as np; sys.path.insert(0, sys.argv[2]);"
        "from engine.imageio import write_image;"
        "write_image(sys.argv[1], np.full((4, 6, 3), 0.125, np.float32))"
    )
    from pathlib import Path

    root = str(Path(__file__).resolve().parents[2])
    cam = HotFolderCamera(tmp_path, trigger=[sys.executable, "-c", script, str(tmp_path / "t.exr"), root], **FAST)
    frame = cam.capture()
    assert frame.metadata["file"] == "t.exr" and frame.image.shape == (4, 6, 3)
    failing = HotFolderCamera(tmp_path, trigger=[sys.executable, "-c", "import sys; sys.exit('camera busy')"], **FAST)
    with pytest.raises(DeviceError, match="exit code 1: camera busy"):
        failing.capture()


@pytest.mark.parametrize(
    "options, match",
    [
        (dict(trigger="gphoto2 --trigger-capture"), "list of command arguments"),
        (dict(resolution=(0, 5)), "resolution"),
        (dict(timeout=-1), "timeout"),
    ],
)
def test_bad_options(tmp_path, options, match):
    with pytest.raises(InputError, match=match):
        HotFolderCamera(tmp_path, **options)


def test_exposure_is_recorded_not_controlled(tmp_path):
    cam = HotFolderCamera(tmp_path, exposure=0.25)
    cam.exposure = 0.25  # unchanged: fine (the Recorder restores it)
    with pytest.raises(InputError, match="set on the camera"):
        cam.exposure = 0.125
    with pytest.raises(DeviceError, match="does not exist"):
        HotFolderCamera(tmp_path / "missing")


def test_open_rig_pairs_a_given_projector(tmp_path):
    from devices.virtual import open_rig as open_virtual

    with open_virtual("cornell", ideal=True) as virtual:
        rig = devices.open_rig(f"hotfolder:{tmp_path}", projector=virtual.projector, resolution=(H, W))
        assert rig.name == f"hotfolder:{tmp_path}" and rig.camera.resolution == (H, W)
    with pytest.raises(InputError, match="needs a folder"):
        devices.open_rig("hotfolder")
    with pytest.raises(InputError, match=r"projector options \['settle'\] only apply to a projector opened by name"):
        devices.open_rig(f"hotfolder:{tmp_path}", projector=virtual.projector, settle=0.2)


def test_open_camera_and_probe_name_the_missing_projector_screen(tmp_path):
    from devices.hotfolder import open_camera

    cam = open_camera(tmp_path, resolution=(H, W), exposure=0.5)
    assert isinstance(cam, HotFolderCamera) and cam.resolution == (H, W) and cam.exposure == 0.5
    (entry,) = [a for a in devices.available() if a.name == "hotfolder:FOLDER"]
    assert not entry.ok and "no second screen" in entry.reason  # one offscreen test screen
    with pytest.raises(DeviceError, match="no second screen for the projector"):
        devices.open_rig(f"hotfolder:{tmp_path}", resolution=(H, W))  # default projector: the second screen


def test_a_file_that_arrives_before_the_trigger_is_refused_by_name(tmp_path):
    script = "import sys; open(sys.argv[1], 'w').close()"
    marker = tmp_path.parent / (tmp_path.name + "_fired")
    cam = HotFolderCamera(tmp_path, trigger=[sys.executable, "-c", script, str(marker)], **FAST)
    write_image(tmp_path / "stray.exr", np.zeros((H, W, 3), np.float32))  # the camera fired on its own
    with pytest.raises(DeviceError, match=r"received 'stray.exr' before the camera was triggered: a frame taken for"):
        cam.capture()
    assert not marker.exists()  # the camera was not fired for a frame that would be misattributed
    assert (tmp_path / "stray.exr").exists()  # nothing deleted


def test_waits_go_through_the_paired_projectors_idle(tmp_path):
    waits = []
    cam = HotFolderCamera(tmp_path, poll=0.01, timeout=0.05)
    cam.set_idle(lambda s: (waits.append(s), time.sleep(s)))
    with pytest.raises(DeviceError, match="no new image arrived"):
        cam.capture()
    assert waits and set(waits) == {0.01}


def test_raw_files_keep_the_sensor_orientation_everywhere(tmp_path, make_dng):
    """A camera's orientation tag (here: rotated 90°) can change between shots of a fixed rig; its
    pixel grid cannot. Every reader decodes RAW files in the sensor's orientation."""
    from engine.imageio import read_image
    from engine.raw import decode_raw

    mosaic = np.full((H, W), 64 + 500, np.uint16)
    mosaic[:2, :] = 4000  # the top rows clip
    rotated = make_dng(mosaic, orientation=6)
    assert decode_raw(rotated).image.shape == (H, W, 3) and decode_raw(rotated).saturated[0].all()
    (tmp_path / "r.dng").write_bytes(rotated)
    assert read_image(tmp_path / "r.dng").shape == (H, W, 3)
    folder = tmp_path / "tether"
    folder.mkdir()
    cam = HotFolderCamera(folder, **FAST)
    (folder / "IMG_1.dng").write_bytes(rotated)
    frame = cam.capture()
    assert frame.image.shape == (H, W, 3) and frame.saturated[0].all() and not frame.saturated[-1].any()
