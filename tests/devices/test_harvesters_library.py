"""The GenICam backend on the real harvesters: a missing and an invalid ``.cti`` producer, and the
simulated GenTL producer the ``genicam`` wheel ships (``viky.cti``: three "Viky" cameras), each
failure ending in the typed error and one-line message the CLI prints.

Skipped when harvesters is not installed (``.ci/run`` runs the device tests both ways).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("harvesters.core")
genicam = pytest.importorskip("genicam")

from app.main import main  # noqa: E402
from devices.harvesters_camera import HarvestersCamera, probe  # noqa: E402
from engine.errors import DeviceError  # noqa: E402

VIKY = Path(genicam.__file__).parent / "viky.cti"


@pytest.fixture
def viky():
    if not VIKY.is_file():
        pytest.skip("this genicam build ships no simulated producer")
    return VIKY


def _cli_error(capsys, *argv) -> str:
    assert main(list(argv)) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err  # one line, no traceback
    return err[0]


def test_missing_and_invalid_producer_files(tmp_path, capsys):
    assert probe()[0].ok
    missing = tmp_path / "maker.cti"
    with pytest.raises(DeviceError, match=r"^no GenTL producer file at '.*maker.cti' \(the camera maker's .cti\)$"):
        HarvestersCamera(missing)
    missing.write_text("not a shared library")
    with pytest.raises(DeviceError, match=r"^loading the GenTL producer failed: .*maker.cti: (file too|invalid ELF)"):
        HarvestersCamera(missing)
    line = _cli_error(capsys, "devices", "--check", f"harvesters:{missing}")
    assert line.startswith("albedit devices: error: loading the GenTL producer failed:")


def test_the_librarys_own_error_log_stays_off_the_terminal(tmp_path):
    """harvesters logs each failure with a traceback to stderr unless given a logger; the CLI
    must print the one-line error only."""
    import os
    import subprocess
    import sys

    bad = tmp_path / "maker.cti"
    bad.write_text("not a shared library")
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYTHONPATH=str(root))
    out = subprocess.run([sys.executable, "-m", "app.main", "devices", "--check", f"harvesters:{bad}"],
                         cwd=root, env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 1
    (line,) = out.stderr.strip().splitlines()
    assert line.startswith(f"albedit devices: error: loading the GenTL producer failed: {bad}: ")


def test_simulated_camera_captures_linear_frames(viky):
    cam = HarvestersCamera(viky, serial="1")
    try:
        assert cam.pixel_format == "Mono8" and cam.resolution == (400, 400)  # RGBa8 is not linear-unpacked
        assert cam.fingerprint["serial"] == "1" and cam.fingerprint["model"]  # a calibration is of this body
        assert cam.warnings == [
            "the camera has no ExposureTime feature: radiance is in relative units (exposure recorded as 1 s)"
        ]
        frame = cam.capture()
        assert frame.image.shape == (400, 400, 3) and frame.image.dtype == np.float32
        assert frame.exposure == 1.0 and frame.gain == 1.0 and frame.metadata["top_code"] == 255
        assert 0.0 <= frame.image.min() and frame.image.max() <= 1.0 and frame.image.max() > 0
        np.testing.assert_array_equal(frame.image[..., 0], frame.image[..., 2])
        with pytest.raises(DeviceError, match="the camera has no ExposureTime feature: its exposure cannot be set"):
            cam.exposure = 0.01
    finally:
        cam.close()


def test_no_frame_within_the_timeout_and_the_next_one_arrives(viky):
    cam = HarvestersCamera(viky, index=0, timeout=0.3)
    try:
        rate = cam.node_map.AcquisitionFrameRate
        rate.value = rate.min  # one frame a second: none can arrive within 0.3 s
        with pytest.raises(DeviceError, match=r"no complete frame from the camera within 0.3 s"):
            cam.capture()
        rate.value = 20.0
        assert cam.capture().image.shape == (400, 400, 3)  # acquisition was stopped and restarts cleanly
    finally:
        cam.close()


def test_unknown_camera_is_a_plain_error(viky):
    with pytest.raises(DeviceError, match=r"^opening the camera failed: no device found: provide sufficient search"):
        HarvestersCamera(viky, serial="7")
    with pytest.raises(DeviceError, match=r"^there is no camera 5: 3 found through viky.cti$"):
        HarvestersCamera(viky, index=5)
