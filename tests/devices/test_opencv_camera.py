"""The OpenCV backend on real files: an MJPG video and a 16-bit PNG image sequence."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import devices
from devices._linearize import ResponseCurve, calibrate_response, response_curve
from devices.base import Frame
from devices.opencv_camera import open_camera
from engine.errors import DeviceError, InputError
from tests.standins import check_standin, stands_in_for

H, W = 48, 64


def _write_sequence(folder, codes_list, dtype=np.uint16):
    for i, codes in enumerate(codes_list):
        assert cv2.imwrite(str(folder / f"f_{i:04d}.png"), np.ascontiguousarray(codes[:, :, ::-1].astype(dtype)))
    return str(folder / "f_%04d.png")


@pytest.fixture
def radiance():
    rng = np.random.default_rng(7)
    return rng.uniform(0.02, 0.9, size=(H, W, 3))


def test_image_sequence_16bit_is_linearised_by_a_known_curve(tmp_path, radiance):
    gamma = 2.2
    codes = np.rint(radiance ** (1 / gamma) * 65535).astype(np.uint16)
    codes[0, 0] = 65535  # one clipped pixel
    pattern = _write_sequence(tmp_path, [codes, codes])
    cam = open_camera(pattern, response=f"gamma:{gamma}", exposure=0.5, gain=2.0)
    try:
        assert cam.resolution == (H, W)
        frame = cam.capture()
        assert isinstance(frame, Frame)
        assert frame.image.dtype == np.float32 and frame.image.shape == (H, W, 3)
        expected = (codes / 65535.0) ** gamma / (0.5 * 2.0)
        np.testing.assert_allclose(frame.image, expected, rtol=1e-4, atol=1e-6)
        assert frame.saturated[0, 0] and frame.saturated.sum() == 1
        assert frame.exposure == 0.5 and frame.gain == 2.0
        assert frame.metadata["response"] == "gamma 2.2"
        cam.exposure = 0.5  # unchanged: accepted (the Recorder restores it after bracketing)
        with pytest.raises(InputError, match="fixed at 0.5 s"):
            cam.exposure = 0.25  # a file cannot be re-exposed
        cam.capture()
        with pytest.raises(DeviceError, match="no more frames"):
            cam.capture()
    finally:
        cam.close()
    with pytest.raises(DeviceError, match="closed"):
        cam.capture()


def test_default_response_for_16bit_is_linear_and_flagged_assumed(tmp_path, radiance):
    codes = np.rint(radiance * 65535).astype(np.uint16)
    cam = open_camera(_write_sequence(tmp_path, [codes]))
    try:
        frame = cam.capture()
    finally:
        cam.close()
    np.testing.assert_allclose(frame.image, codes / 65535.0, rtol=1e-5)
    assert frame.metadata["response"] == "linear (assumed)"
    assert any("assuming linear" in w for w in frame.metadata["warnings"])


def test_frames_are_averaged_after_linearisation(tmp_path):
    a = np.full((H, W, 3), 100, np.uint8)
    b = np.full((H, W, 3), 200, np.uint8)
    curve = ResponseCurve.srgb()
    cam = open_camera(_write_sequence(tmp_path, [a, b], dtype=np.uint8), response=curve, average=2)
    try:
        frame = cam.capture()
    finally:
        cam.close()
    expected = (curve.lut[100, 0] + curve.lut[200, 0]) / 2
    np.testing.assert_allclose(frame.image, expected, rtol=1e-6)
    assert frame.metadata["averaged"] == 2


def test_mjpg_video_file_reads_back_linearised(tmp_path):
    path = str(tmp_path / "clip.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (W, H))
    assert writer.isOpened()
    levels = [40, 120, 220]
    for v in levels:
        writer.write(np.full((H, W, 3), v, np.uint8))
    writer.release()
    raw = open_camera(path, response="linear")
    cam = open_camera(path, response="srgb", exposure=0.25)
    assert cam.fingerprint == {"source": path, "api": cam.backend}  # a calibration is of this source
    try:
        for v in levels:
            codes = raw.capture_codes()
            assert np.abs(codes.astype(int) - v).max() <= 4  # MJPG moves codes by a level or few
            frame = cam.capture()
            np.testing.assert_allclose(frame.image, ResponseCurve.srgb().apply(codes) / 0.25, rtol=1e-6)
        with pytest.raises(DeviceError, match="no more frames"):
            cam.capture()
    finally:
        raw.close()
        cam.close()


def test_debevec_recovers_a_known_gamma(tmp_path):
    rng = np.random.default_rng(3)
    scene = rng.uniform(0.01, 1.0, size=(32, 32, 3))
    times = [1 / 64, 1 / 16, 1 / 4, 1.0, 4.0]
    images = [np.rint(np.clip(scene * t, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8) for t in times]
    curve = calibrate_response(images, times)
    truth = np.linspace(0, 1, 256) ** 2.2
    lut = curve.lut[:, 1] / curve.lut[200, 1] * truth[200]
    # Debevec fixes the scale only; compare the shape over the well-exposed codes
    np.testing.assert_allclose(lut[30:250], truth[30:250], rtol=0.15)


def test_response_curve_errors():
    with pytest.raises(InputError, match="non-decreasing"):
        ResponseCurve([0.0, 0.5, 0.4])
    with pytest.raises(InputError, match="response must be"):
        response_curve("log", levels=256)
    with pytest.raises(InputError, match="unsigned-integer"):
        ResponseCurve.srgb().apply(np.zeros((2, 2, 3), np.float32))


def test_bad_sources_and_options(tmp_path):
    with pytest.raises(DeviceError, match="no such video"):
        open_camera(str(tmp_path / "missing.avi"))
    with pytest.raises(DeviceError, match="does not exist"):
        open_camera(str(tmp_path / "nowhere" / "f_%04d.png"))
    (tmp_path / "junk.avi").write_bytes(b"not a video")
    with pytest.raises(DeviceError, match="cannot read"):
        open_camera(str(tmp_path / "junk.avi"))
    codes = np.zeros((H, W, 3), np.uint16)
    with pytest.raises(InputError, match="average"):
        open_camera(_write_sequence(tmp_path, [codes]), average=0)


def test_projector_change_drops_queued_frames(tmp_path):
    seq = [np.full((H, W, 3), 10 * (i + 1), np.uint8) for i in range(6)]
    cam = open_camera(_write_sequence(tmp_path, seq, dtype=np.uint8), response="linear", discard=2)
    try:
        first = cam.capture_codes()[0, 0, 0]
        cam.mark_stale()  # what the projector's shown-callback does
        after = cam.capture_codes()[0, 0, 0]
    finally:
        cam.close()
    assert (first, after) == (10, 40)


def test_open_rig_with_a_given_projector(tmp_path):
    from devices.virtual import open_rig as open_virtual

    with open_virtual("cornell", ideal=True) as virtual:
        proj = virtual.projector
        codes = np.zeros((H, W, 3), np.uint16)
        rig = devices.open_rig(f"opencv:{_write_sequence(tmp_path, [codes, codes])}", projector=proj)
        assert rig.projector is proj and rig.camera.resolution == (H, W)
        assert rig.name.startswith("opencv:")
        rig.camera.close()


@stands_in_for("cv2:VideoCapture")
class FakeV4L2:
    """A scripted stand-in for ``cv2.VideoCapture`` on a V4L2 webcam: gamma-1.6 frames of a known
    radiance at the exposure last set (in 100 microsecond units); refuses auto exposure."""

    _radiance = np.geomspace(1.0, 1000.0, H * W).reshape(H, W)[..., None] * np.array([1.0, 0.8, 0.6])

    def __init__(self, index, *args):
        self.units = 100.0  # 10 ms
        self.grabs = 0
        self.sets: list[tuple[int, float, bool]] = []
        self.released = False

    def isOpened(self):  # noqa: N802 (OpenCV's name)
        return True

    def getBackendName(self):  # noqa: N802
        return "V4L2"

    def set(self, prop, value):
        ok = prop != cv2.CAP_PROP_AUTO_EXPOSURE and not (prop == cv2.CAP_PROP_EXPOSURE and value > 1e5)
        self.sets.append((prop, value, ok))
        if ok and prop == cv2.CAP_PROP_EXPOSURE:
            self.units = value
        return ok

    def get(self, prop):
        return self.units if prop == cv2.CAP_PROP_EXPOSURE else 0.0

    def grab(self):
        self.grabs += 1
        return True

    def read(self):
        lin = np.clip(self._radiance * self.units * 1e-4, 0.0, 1.0)
        rgb = np.rint(lin ** (1 / 1.6) * 255).astype(np.uint8)
        return True, np.ascontiguousarray(rgb[:, :, ::-1])

    def release(self):
        self.released = True


def test_webcam_controls_refusals_recorded_and_response_measured(monkeypatch):
    monkeypatch.setattr(cv2, "VideoCapture", FakeV4L2)
    cam = open_camera(0, exposure=0.002)
    try:
        dev = cam._cap
        assert cam.controls["auto_exposure"] == "refused" and cam.controls["auto_wb"] == 0
        assert cam.controls["exposure"] == pytest.approx(20.0)  # 2 ms in 100 us units
        assert any("refused to switch auto exposure off" in w for w in cam.warnings)
        assert cam.exposure == 0.002
        with pytest.raises(DeviceError, match="refused exposure 20 s"):
            cam.exposure = 20.0
        assert cam.exposure == 0.002  # unchanged after a refusal
        grabs = dev.grabs
        cam.capture()  # first capture after opening drops the driver's queued frames
        assert dev.grabs == grabs + cam.discard == grabs + 4
        curve = cam.calibrate_response([1e-4, 4e-4, 1.6e-3, 6.4e-3, 2.56e-2, 0.1])
        assert curve.name == "debevec" and cam.response is curve and cam.exposure == 0.002
        frame = cam.capture()
        assert frame.metadata["response"] == "debevec" and frame.metadata["controls"]["auto_exposure"] == "refused"
        ok = ~frame.saturated & (frame.image[..., 1] > frame.image[..., 1].max() * 0.05)
        # linear after calibration: radiance ratios match the scene's (Debevec fixes scale only)
        ratio = frame.image[..., 1][ok] / FakeV4L2._radiance[..., 1][ok]
        assert ratio.std() / ratio.mean() < 0.03  # the assumed sRGB curve is off by ~20 % here
    finally:
        cam.close()
    assert dev.released


def test_standin_matches_opencv():
    assert check_standin(FakeV4L2) == []


def test_a_camera_index_with_no_device_is_one_plain_line(capfd):
    """The real VideoCapture on an index with no camera: OpenCV's per-backend warnings stay off
    the terminal, and the CLI prints one line."""
    import glob

    from app.main import main

    index = 97
    if glob.glob(f"/dev/video{index}"):
        pytest.skip(f"/dev/video{index} exists here")
    with pytest.raises(DeviceError,
                       match=rf"^no camera at index {index} \(not attached, or in use by another program\)$"):
        open_camera(index)
    assert main(["devices", "--check", f"opencv:{index}"]) == 1
    err = capfd.readouterr().err.strip().splitlines()
    assert err == [f"albedit devices: error: no camera at index {index} (not attached, or in use by another program)"]
