"""The gphoto2 backend against a scripted stand-in of python-gphoto2 (every exchange must be used).

The stand-in is checked against the real python-gphoto2 when it is installed
(:func:`test_standin_matches_python_gphoto2`); tests/devices/test_gphoto2_library.py drives the real
library with no camera and with its virtual camera.
"""

from __future__ import annotations

import threading
import time
import types

import numpy as np
import pytest

import devices
from devices.gphoto2_camera import GPhoto2Camera, list_cameras, probe
from engine.errors import DeviceError, InputError
from tests.standins import check_standin, stands_in_for

H, W = 32, 48


@stands_in_for("gphoto2:GPhoto2Error")
class GPhoto2Error(Exception):
    def __init__(self, code):
        super().__init__(f"[{code}] libgphoto2 error")
        self.code = code


@stands_in_for("gphoto2:CameraWidget")
class Widget:
    def __init__(self, value, choices):
        self.value, self.choices = value, list(choices)

    def get_value(self):
        return self.value

    def get_choices(self):
        return iter(self.choices)

    def set_value(self, value):
        self.value = value


SHUTTERS = ["bulb", "30", "1", "0.5", "1/4", "1/8", "1/60", "1/250"]
ISOS = ["Auto", "100", "200", "400"]


class Script:
    """Expected calls in order: (method, args, result); a result that is an exception is raised."""

    def __init__(self, steps):
        self.steps = list(steps)
        self.used = 0
        self.lock = threading.Lock()

    def __call__(self, method, *args):
        with self.lock:
            assert self.used < len(self.steps), f"unexpected call {method}{args}: script exhausted"
            want, want_args, result = self.steps[self.used]
            shown = tuple(a.value if isinstance(a, Widget) else a for a in args)
            assert (method, shown) == (want, tuple(want_args)), \
                f"call {self.used}: got {method}{shown}, expected {want}{tuple(want_args)}"
            self.used += 1
        if isinstance(result, BaseException):
            raise result
        return result() if callable(result) and not isinstance(result, Widget) else result

    def finished(self):
        assert self.used == len(self.steps), f"unused scripted exchanges: {self.steps[self.used:]}"


@stands_in_for("gphoto2:CameraList")
class CameraList:
    def __init__(self, pairs):
        self.pairs = list(pairs)

    def items(self):
        return iter(self.pairs)


@stands_in_for("gphoto2:Camera")
class Camera:
    """python-gphoto2's Camera: every call goes to the class's script."""

    script: Script

    @classmethod
    def autodetect(cls):
        return CameraList(cls.script("autodetect"))

    def init(self):
        return self.script("init")

    def exit(self):
        return self.script("exit")

    def get_single_config(self, name):
        return self.script("get_single_config", name)

    def set_single_config(self, name, widget):
        return self.script("set_single_config", name, widget)

    def capture(self, type):  # noqa: A002 (the library's name)
        return self.script("capture", type)

    def file_get(self, folder, file, type):  # noqa: A002
        return self.script("file_get", folder, file, type)

    def file_delete(self, folder, file):
        return self.script("file_delete", folder, file)


@stands_in_for("gphoto2:CameraFilePath", attributes=("folder", "name"))
class FilePath:
    def __init__(self, folder, name):
        self.folder, self.name = folder, name


@stands_in_for("gphoto2:CameraFile")
class CameraFile:
    def __init__(self, data):
        self.data = data

    def get_data_and_size(self):
        return memoryview(self.data)


@stands_in_for("gphoto2")
class FakeModule:
    """The module attributes the backend uses."""

    Camera = Camera
    GPhoto2Error = GPhoto2Error
    GP_CAPTURE_IMAGE = 0
    GP_FILE_TYPE_NORMAL = 1


def fake_gphoto2(script):
    camera = type("Camera", (Camera,), {"script": script})
    public = {k: v for k, v in vars(FakeModule).items() if not k.startswith("_")}
    return types.SimpleNamespace(**public | {"Camera": camera})


@pytest.mark.parametrize("standin", [GPhoto2Error, Widget, CameraList, Camera, FilePath, CameraFile, FakeModule],
                         ids=lambda c: c.__name__)
def test_standin_matches_python_gphoto2(standin):
    pytest.importorskip("gphoto2")
    assert check_standin(standin) == []


def opening(*, shutter="1/60", iso="200", target=True):
    """The exchanges of GPhoto2Camera(exposure=1/8, iso=200) on a camera with these settings."""
    steps = [("init", (), None)]
    steps.append(("get_single_config", ("capturetarget",),
                  Widget("Memory card", ["Internal RAM", "Memory card"]) if target else GPhoto2Error(-2)))
    if target:
        steps.append(("set_single_config", ("capturetarget", "Internal RAM"), None))
    steps += [
        ("get_single_config", ("imageformat",),
         Widget("Large Fine JPEG", ["Large Fine JPEG", "RAW + Large Fine JPEG", "RAW"])),
        ("set_single_config", ("imageformat", "RAW"), None),
        ("get_single_config", ("iso",), Widget("Auto", ISOS)),
        ("set_single_config", ("iso", iso), None),
        ("get_single_config", ("shutterspeed",), Widget(shutter, SHUTTERS)),
        ("get_single_config", ("shutterspeed",), Widget(shutter, SHUTTERS)),
        ("set_single_config", ("shutterspeed", "1/8"), None),
        ("get_single_config", ("iso",), Widget(iso, ISOS)),
    ]
    return steps


def shot(name, data, *, delete_result=None):
    path = FilePath("/", name)
    return [
        ("capture", (0,), path),
        ("file_get", ("/", name, 1), CameraFile(data)),
        ("file_delete", ("/", name), delete_result),
    ]


def test_capture_downloads_deletes_and_decodes_linearly(make_dng):
    mosaic = np.full((H, W), 64 + 1000, np.uint16)
    mosaic[0, 0] = 4000
    raw = make_dng(mosaic)
    script = Script(opening() + shot("capt0000.dng", raw) + shot("capt0001.dng", raw, delete_result=GPhoto2Error(-6))
                    + [("exit", (), None)])
    cam = GPhoto2Camera(exposure=0.1, iso=200, gp=fake_gphoto2(script))
    assert cam.exposure == 0.125 and cam.gain == 2.0  # nearest shutter 1/8 s; ISO 200 / base 100
    frame = cam.capture()
    np.testing.assert_allclose(frame.image[4:, 4:], 1000 / (4000 - 64) / (0.125 * 2.0), rtol=1e-4)
    assert frame.saturated[0, 0] and not frame.saturated[4:, 4:].any()
    assert frame.metadata["raw_name"] == "capt0000.dng" and cam.last_raw == raw
    assert frame.metadata["settings"] == {"capture_target": "Internal RAM", "image_format": "RAW", "iso": "200",
                                          "exposure": "1/8"}
    assert cam.resolution == (H, W) and cam.warnings == []
    cam.capture()  # the body refuses the delete: recorded, not fatal
    assert "deleting capt0001.dng from the camera failed" in cam.warnings[0]
    cam.close()
    cam.close()  # idempotent: exit once
    script.finished()


def test_exposure_snaps_to_nearest_shutter_speed_and_reports_it():
    script = Script(
        opening()
        + [
            ("get_single_config", ("shutterspeed",), Widget("1/8", SHUTTERS)),
            ("set_single_config", ("shutterspeed", "1/250"), None),
            ("get_single_config", ("shutterspeed",), Widget("1/250", SHUTTERS)),
            ("set_single_config", ("shutterspeed", "30"), None),
            ("exit", (), None),
        ]
    )
    cam = GPhoto2Camera(exposure=1 / 8, iso="200", gp=fake_gphoto2(script))
    cam.exposure = 1 / 300  # nearest offered: 1/250
    assert cam.exposure == 1 / 250
    cam.exposure = 1 / 250  # no change, no exchange
    cam.exposure = 40.0
    assert cam.exposure == 30.0
    with pytest.raises(InputError, match=r"exposure 0.001 s is outside the camera's shutter speeds "
                                         r"\(1/250 .. 30 s\); valid choices: 1/250, 1/60"):
        cam.exposure = 1e-3  # more than half a stop beyond the shortest: refused, nothing sent
    with pytest.raises(InputError, match="exposure"):
        cam.exposure = -1
    cam.close()
    script.finished()


def test_invalid_iso_lists_the_choices():
    steps = opening()[:5] + [("get_single_config", ("iso",), Widget("Auto", ISOS)), ("exit", (), None)]
    script = Script(steps)
    with pytest.raises(InputError, match="iso 150 is not offered by this camera; valid choices: Auto, 100, 200, 400"):
        GPhoto2Camera(exposure=1 / 8, iso=150, gp=fake_gphoto2(script))
    script.finished()


def test_camera_without_capture_target_warns():
    script = Script(opening(target=False) + [("exit", (), None)])
    cam = GPhoto2Camera(exposure=1 / 8, iso=200, gp=fake_gphoto2(script))
    assert "no capture target setting" in cam.warnings[0]
    cam.close()
    script.finished()


@pytest.mark.parametrize(
    "code, words",
    [
        (-105, "no camera found"),
        (-52, "another program holds it"),
        (-53, "claimed by another program"),
        (-110, "camera is busy"),
        (-10, "did not answer in time"),
        (-7, "input/output error"),
        (-60, "could not lock"),
        (-115, "no space left"),
        (-99, "libgphoto2 error -99"),
    ],
)
def test_error_codes_become_plain_words(code, words):
    script = Script([("init", (), GPhoto2Error(code))])
    with pytest.raises(DeviceError, match=f"opening the camera failed: .*{words}"):
        GPhoto2Camera(gp=fake_gphoto2(script))
    script.finished()


def test_capture_error_still_deletes_nothing_and_maps_busy(make_dng):
    script = Script(opening() + [("capture", (0,), GPhoto2Error(-110)), ("exit", (), None)])  # exit: session dropped
    cam = GPhoto2Camera(exposure=1 / 8, iso=200, gp=fake_gphoto2(script))
    with pytest.raises(DeviceError, match="capturing failed: the camera is busy"):
        cam.capture()
    cam.close()
    script.finished()


def test_download_failure_still_deletes_the_shot():
    path = FilePath("/store", "IMG_1.CR2")
    script = Script(
        opening()
        + [("capture", (0,), path), ("file_get", ("/store", "IMG_1.CR2", 1), GPhoto2Error(-7)),
           ("file_delete", ("/store", "IMG_1.CR2"), None), ("exit", (), None)]
    )
    cam = GPhoto2Camera(exposure=1 / 8, iso=200, gp=fake_gphoto2(script))
    with pytest.raises(DeviceError, match="downloading IMG_1.CR2 failed: input/output error"):
        cam.capture()
    cam.close()
    script.finished()


def test_jpeg_instead_of_raw_is_refused():
    script = Script(opening() + shot("capt0000.jpg", b"\xff\xd8") + [("exit", (), None)])
    cam = GPhoto2Camera(exposure=1 / 8, iso=200, gp=fake_gphoto2(script))
    with pytest.raises(DeviceError, match="not a RAW file"):
        cam.capture()
    cam.close()
    script.finished()


def test_a_hung_call_times_out_and_blocks_further_calls():
    release = threading.Event()
    script = Script(opening() + [("capture", (0,), lambda: release.wait(5)), ("exit", (), None)])
    cam = GPhoto2Camera(exposure=1 / 8, iso=200, timeout=0.2, gp=fake_gphoto2(script))
    with pytest.raises(DeviceError, match="did not finish capturing within"):
        cam.capture()
    with pytest.raises(DeviceError, match="has not answered an earlier capturing"):
        cam.capture()
    release.set()
    cam._dog._hung.join(5)
    cam.close()
    script.finished()


def test_listing_and_probe():
    script = Script([("autodetect", (), [("Nikon DSC D7100", "usb:001,004")]), ("autodetect", (), []),
                     ("autodetect", (), GPhoto2Error(-7))])
    gp = fake_gphoto2(script)
    assert list_cameras(gp=gp) == [("Nikon DSC D7100", "usb:001,004")]
    assert [str(a) for a in probe(gp=gp)] == [
        "gphoto2: unavailable — no camera detected (connected by USB, switched on, not in mass-storage mode?)"]
    (entry,) = probe(gp=gp)
    assert not entry.ok and "input/output error" in entry.reason
    script.finished()


def test_missing_library_is_a_plain_device_error(without_modules):
    without_modules("gphoto2")
    with pytest.raises(DeviceError, match=r"python-gphoto2 is not installed; "
                                          r"install the optional extra: pip install 'albedit\[gphoto2\]'"):
        GPhoto2Camera()
    (entry,) = probe()
    assert not entry.ok and "not installed" in entry.reason


def test_open_rig_with_given_projector():
    from devices.virtual import open_rig as open_virtual

    script = Script(opening() + [("exit", (), None)])
    with open_virtual("cornell", ideal=True) as virtual:
        rig = devices.open_rig("gphoto2", projector=virtual.projector, exposure=1 / 8, iso=200, gp=fake_gphoto2(script))
        assert rig.name == "gphoto2" and rig.projector is virtual.projector
        rig.camera.close()
    script.finished()


def reapply(shutter="1/8"):
    """A reconnection: a fresh handle's init, then every setting written again (some bodies forget
    them per session)."""
    return [
        ("init", (), None),
        ("get_single_config", ("capturetarget",), Widget("Memory card", ["Internal RAM", "Memory card"])),
        ("set_single_config", ("capturetarget", "Internal RAM"), None),
        ("get_single_config", ("imageformat",), Widget("RAW", ["Large Fine JPEG", "RAW"])),
        ("set_single_config", ("imageformat", "RAW"), None),
        ("get_single_config", ("iso",), Widget("200", ISOS)),
        ("set_single_config", ("iso", "200"), None),
        ("get_single_config", ("shutterspeed",), Widget(shutter, SHUTTERS)),
        ("set_single_config", ("shutterspeed", "1/8"), None),
    ]


def test_unplugged_mid_capture_then_reconnects_and_reapplies_settings(make_dng):
    raw = make_dng(np.full((H, W), 1064, np.uint16))
    script = Script(
        opening()
        + [("capture", (0,), GPhoto2Error(-7)), ("exit", (), GPhoto2Error(-7))]  # unplugged: exit fails too
        + reapply()
        + shot("capt0001.dng", raw)
        + [("exit", (), None)]
    )
    cam = GPhoto2Camera(exposure=1 / 8, iso=200, release_after=None, gp=fake_gphoto2(script))
    with pytest.raises(DeviceError, match="capturing failed: input/output error .* USB cable"):
        cam.capture()
    assert not cam.connected
    frame = cam.capture()  # plugged back in: a fresh session with the same settings
    assert cam.connected and frame.metadata["raw_name"] == "capt0001.dng"
    cam.close()
    script.finished()


def test_full_card_is_a_plain_error_and_the_shot_is_not_downloaded():
    script = Script(opening() + [("capture", (0,), GPhoto2Error(-115)), ("exit", (), None)])
    cam = GPhoto2Camera(exposure=1 / 8, iso=200, release_after=None, gp=fake_gphoto2(script))
    with pytest.raises(DeviceError, match="no space left .* delete images"):
        cam.capture()
    cam.close()
    script.finished()


def test_session_released_when_idle_and_reopened_by_the_next_capture(make_dng):
    raw = make_dng(np.full((H, W), 1064, np.uint16))
    released = threading.Event()
    script = Script(
        opening()
        + shot("capt0000.dng", raw)
        + [("exit", (), released.set)]  # the idle timer releases the session
        + reapply()
        + shot("capt0001.dng", raw)
        + [("exit", (), None)]  # release() by hand
        + reapply()
        + shot("capt0002.dng", raw)
        + [("exit", (), None)]  # close()
    )
    cam = GPhoto2Camera(exposure=1 / 8, iso=200, release_after=None, gp=fake_gphoto2(script))
    cam.release_after = 0.05  # armed after each capture
    cam.capture()
    assert released.wait(5)
    # the timer thread marks the session closed just after ``exit`` returns: wait for it
    deadline = time.monotonic() + 5
    while cam.connected and time.monotonic() < deadline:
        time.sleep(0.005)
    assert not cam.connected
    cam.release_after = None
    cam.capture()
    assert cam.connected
    cam.release()
    assert not cam.connected
    assert cam.capture().metadata["raw_name"] == "capt0002.dng"
    cam.close()
    script.finished()


def test_clipped_pixels_are_completed_by_the_recorders_bracket_at_snapped_shutter_speeds(make_dng):
    """The one HDR merge (the acquisition Recorder's) through this backend's exposure snapping."""
    from engine.acquire import Recorder

    black, white = 64, 4000
    span = white - black
    # radiance (fraction of full scale per second at gain 1): left half 4, right half 16
    radiance = np.where(np.arange(W) < W // 2, 4.0, 16.0)[None, :].repeat(H, 0)

    def dng(t):
        frac = radiance * t * 2.0  # gain 2 (ISO 200 / 100)
        return make_dng(np.where(frac >= 1, white, np.rint(black + frac * span)).astype(np.uint16))

    script = Script(
        opening()
        + shot("capt0000.dng", dng(1 / 8))  # the right half clips at 1/8 s (16 * 0.25 = 4 > 1)
        + [("get_single_config", ("shutterspeed",), Widget("1/8", SHUTTERS)),
           ("set_single_config", ("shutterspeed", "1/60"), None)]
        + shot("capt0001.dng", dng(1 / 60))  # 1/8 / 8 = 1/64 s snaps to 1/60 s
        + [("get_single_config", ("shutterspeed",), Widget("1/60", SHUTTERS)),
           ("set_single_config", ("shutterspeed", "1/8"), None)]
        + [("exit", (), None)]
    )
    cam = GPhoto2Camera(exposure=1 / 8, iso=200, release_after=None, gp=fake_gphoto2(script))

    class Projector:
        resolution, bit_depth = (4, 4), 8

        def show(self, image):
            pass

    rig = types.SimpleNamespace(camera=cam, projector=Projector())
    image = Recorder(rig, brackets=2, bracket_step=8.0).capture("flat", np.zeros((4, 4, 3), np.float32))
    np.testing.assert_allclose(image[4:-4, 4 : W // 2 - 4], 4.0, rtol=2e-3)
    np.testing.assert_allclose(image[4:-4, W // 2 + 4 : -4], 16.0, rtol=2e-3)
    assert cam.exposure == 0.125 and cam.settings["exposure"] == "1/8"  # restored after the bracket
    cam.close()
    script.finished()


def test_available_says_when_the_projector_screen_is_missing(monkeypatch):
    import devices.gphoto2_camera as backend

    script = Script([("autodetect", (), [("Canon EOS 80D", "usb:001,005")])])
    monkeypatch.setattr(backend, "_gphoto2", lambda: fake_gphoto2(script))
    (entry,) = [a for a in devices.available() if a.name.startswith("gphoto2")]
    assert entry.name == "gphoto2:usb:001,005" and entry.reason.startswith("Canon EOS 80D")
    assert not entry.ok and "no second screen" in entry.reason  # the offscreen test platform has one screen
    assert "pass projector='qtscreen:0'" in entry.reason
    script.finished()
