"""The one-frame health check on the virtual rig and on a hot-folder rig."""

from __future__ import annotations

import numpy as np
import pytest

from devices.health import check_rig
from engine.errors import DeviceError, InputError
from engine.imageio import write_image


def test_check_virtual_rig_reports_resolutions_frame_and_saturation():
    report = check_rig("virtual:cornell", ideal=True)
    lines = report.splitlines()
    assert lines[0] == "rig virtual:cornell: opened" and lines[-1] == "rig closed"
    from devices.registry import open_rig

    with open_rig("virtual:cornell", ideal=True) as rig:
        (h, w), (hp, wp) = rig.camera.resolution, rig.projector.resolution
        exposure = rig.camera.exposure
    assert f"{w}x{h}" in lines[1] and f"{wp}x{hp}, 24-bit" in lines[2]  # the ideal projector: float32 input, unrounded
    assert f"exposure {exposure:g} s" in report
    assert "saturated: 0.00% of pixels" in report


def test_check_counts_saturated_pixels_on_a_hotfolder_rig(tmp_path):
    from devices.virtual import open_rig as open_virtual

    image = np.full((10, 20, 3), 0.5, np.float32)
    image[:5, :10] = 1.0  # a quarter clipped
    write_image(tmp_path / "scratch.png", image, dtype="uint16")
    png = (tmp_path / "scratch.png").read_bytes()
    folder = tmp_path / "hot"
    folder.mkdir()
    with open_virtual("cornell", ideal=True) as virtual:
        import threading

        timer = threading.Timer(0.1, lambda: (folder / "shot.png").write_bytes(png))
        timer.start()
        report = check_rig(f"hotfolder:{folder}", projector=virtual.projector, poll=0.01, timeout=5.0)
        timer.join()
    assert "saturated: 25.00% of pixels" in report and "more than 1% of pixels clipped" in report
    assert "frame: 20x10" in report


def test_check_propagates_open_errors(tmp_path):
    with pytest.raises(DeviceError, match="does not exist"):
        check_rig(f"hotfolder:{tmp_path / 'missing'}")
    with pytest.raises(InputError, match="unknown rig backend"):
        check_rig("nosuch:thing")


def test_check_rig_with_device(device_name):
    """Hardware: ``pytest tests/devices --device gphoto2`` (or any rig name) takes one real frame."""
    report = check_rig(device_name)
    assert report.splitlines()[-1] == "rig closed" and "saturated:" in report
