"""Issue 11, items 9 and 12-15: per-frame noise, hostile scene files, bad arguments, recolor limits, read-only."""

from __future__ import annotations

import errno
import json
import os

import numpy as np
import pytest

from engine.acquire import Recorder
from engine.decompose import Decomposition
from engine.errors import Cancelled, InputError
from engine.imageio import read_image, read_mask, write_image
from engine.session import Session
from engine.trust import recolor_trusted
from engine.workflow import load_trusted
from tests.faults.conftest import captures_of, refused

# ----------------------------------------------------------------------------- 9: noise per frame


def test_no_two_frames_share_their_noise_and_a_resumed_run_takes_the_same_frames(open_rig, tmp_path, tally):
    from engine.workflow import open_session_for_rig, run_calibration

    rig = open_rig()
    recorder = Recorder(rig, frames=2)
    pattern = recorder.black()
    calibration, photograph = recorder.capture("cal-black", pattern), recorder.capture("acq-photograph", pattern)
    assert not np.array_equal(calibration, photograph)  # the same light: other noise
    again = Recorder(open_rig(), frames=2)  # another process, the same rig seed
    np.testing.assert_array_equal(again.capture("acq-photograph", pattern), photograph)
    # a calibration interrupted after 9 captures and resumed by a new process takes the frames an uninterrupted one does
    run_calibration(rig, open_session_for_rig(tmp_path / "a", rig), levels=5)
    second = open_rig()
    calls = iter(range(1000))
    with pytest.raises(Cancelled):
        run_calibration(second, open_session_for_rig(tmp_path / "b", second), levels=5,
                        should_stop=lambda: next(calls) >= 9)
    tally.injected += 1
    third = open_rig()
    run_calibration(third, open_session_for_rig(tmp_path / "b", third), levels=5)
    tally.resumed += 1
    a, b = Session.open(tmp_path / "a"), Session.open(tmp_path / "b")
    assert [c.name for c in a.captures] == [c.name for c in b.captures]
    for c in a.captures:  # the files differ in their time stamps only
        np.testing.assert_array_equal(b.read_capture(c.name), a.read_capture(c.name))


# ----------------------------------------------------------------------------- 12: scene files


def _scene(tmp_path, change):
    from devices.virtual.scene import SCENE_DIR

    data = json.loads((SCENE_DIR / "cornell.json").read_text())
    change(data)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(data) if not isinstance(data, str) else data)
    return path


def _set(path, value):
    def change(data):
        node = data
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return change


SCENES = [
    ("patch", _set(["patch_size"], 0.001), "cuts scene 'cornell' into 6.23e+06 patches; at most 8000"),
    ("big-int", _set(["patch_size"], 10**400), "patch_size must be a finite number"),
    ("emission", _set(["surfaces", 0, "emission"], [1e308, 1e308, 1e308]), "surfaces[0].emission must be <= 1000000.0"),
    ("negative", _set(["surfaces", 0, "albedo"], [-0.2, 0.5, 0.5]), "a negative albedo reflects negative light"),
    ("corner", _set(["surfaces", 1, "corners", 0, 0], 10**400), "surfaces[1].corners must be finite"),
]


@pytest.mark.parametrize(("label", "change", "match"), SCENES, ids=[s[0] for s in SCENES])
def test_hostile_scene_files_get_one_line(tmp_path, albedit, tally, label, change, match):
    scene = _scene(tmp_path, change)
    tally.injected += 1
    refused(albedit, tally, "calibrate", tmp_path / "s", "--rig", f"virtual:{scene}", "--resolution", "16",
            match=match)
    assert not (tmp_path / "s").exists()


def test_a_deeply_nested_scene_and_a_device_path_get_one_line(tmp_path, albedit, tally):
    (tmp_path / "deep.json").write_text("[" * 200_000 + "]" * 200_000)
    refused(albedit, tally, "calibrate", tmp_path / "s", "--rig", f"virtual:{tmp_path / 'deep.json'}",
            match="nests its JSON too deeply")
    refused(albedit, tally, "calibrate", tmp_path / "s", "--rig", "virtual:/dev/zero", match="is not a regular file")
    tally.injected += 2


# ----------------------------------------------------------------------------- 13: arguments


ARGUMENTS = [
    (["capture", "{s}", "--target", "right_wall", "--frames", "0"], "frames must be an integer in 1..256"),
    (["capture", "{s}", "--target", "right_wall", "--frames", "-1"], "frames must be an integer in 1..256"),
    (["capture", "{s}", "--target", "right_wall", "--frames", "1000000"], "frames must be an integer in 1..256"),
    (["capture", "{s}", "--target", "right_wall", "--threshold", "nan"], "threshold must be a relative error"),
    (["capture", "{s}", "--target", "right_wall", "--order", "9"], "order must be an integer in 1..8"),
    (["demo", "-o", "{tmp}/d", "--denoise", "1000000"], "the denoise radius must be an integer in 0..1024"),
    (["demo", "-o", "{tmp}/d", "--frames", "0"], "frames must be an integer in 1..256"),
    (["calibrate", "{tmp}/c", "--levels", "1"], "levels must be an integer in 3..256"),
    (["recolor", "{s}", "--kappa", "2", "-o", "{tmp}/o.exr", "--denoise", "-3"], "the denoise radius must be"),
]


@pytest.mark.parametrize(("args", "match"), ARGUMENTS, ids=[" ".join(a[0:1] + a[-2:]) for a, _ in ARGUMENTS])
def test_bad_arguments_are_refused_before_the_first_capture(captured, tmp_path, albedit, tally, args, match):
    kept = captures_of(captured)
    tally.injected += 1
    refused(albedit, tally, *[a.format(s=captured, tmp=tmp_path) for a in args], match=match)
    assert captures_of(captured) == kept and not (tmp_path / "c").exists() and not (tmp_path / "d").exists()


def test_an_empty_mask_is_refused_before_any_capture(tmp_path, albedit, tally):
    write_image(tmp_path / "empty.png", np.zeros((24, 24), np.uint8))
    tally.injected += 1
    refused(albedit, tally, "capture", tmp_path / "s", "--resolution", "24", "--calibration", tmp_path / "nothing",
            "--target", f"wall={tmp_path / 'empty.png'}", match="target 'wall' is empty")
    assert not (tmp_path / "s").exists()


def test_the_calibration_levels_are_checked_before_the_first_capture(open_rig, tmp_path, tally):
    from engine.workflow import open_session_for_rig, run_calibration

    rig = open_rig()
    session = open_session_for_rig(tmp_path / "s", rig)
    tally.injected += 1
    with pytest.raises(InputError, match="count must be an integer ≥ 3"):
        run_calibration(rig, session, levels=1)
    assert not session.captures


@pytest.mark.parametrize(
    ("pixels", "painted"),
    [
        (np.full((4, 4), 128, np.uint8), 16),  # 50 % grey: sRGB-decoding would make it 21 %, not "painted"
        (np.dstack([np.zeros((4, 4, 3)), np.eye(4)[..., None] * 255]).astype(np.uint8), 4),  # alpha only
        (np.dstack([np.full((4, 4, 3), 255), np.eye(4)[..., None] * 255]).astype(np.uint8), 4),  # white, alpha marks
        (np.eye(4, dtype=np.uint8)[..., None].repeat(3, 2) * 1, 4),  # the faintest grey counts
    ],
    ids=["grey-50", "alpha-only", "white-with-alpha", "one-level"],
)
def test_masks_count_any_non_zero_luminance_or_alpha(tmp_path, pixels, painted):
    write_image(tmp_path / "m.png", pixels)
    assert int(read_mask(tmp_path / "m.png").sum()) == painted


# ----------------------------------------------------------------------------- 14: recolor limits


def test_recolor_refuses_a_kappa_that_overflows(captured, tmp_path, albedit, tally):
    tally.injected += 1
    refused(albedit, tally, "recolor", captured, "--kappa", "1e30", "-o", tmp_path / "o.exr",
            match="gives values that are not finite: κ^2 multiplies the last interaction component")
    assert not (tmp_path / "o.exr").exists()


@pytest.mark.parametrize(
    ("arrays", "match"),
    [
        ((np.ones((2, 4, 4, 0), np.float32), np.ones((4, 4, 0), np.float32), np.eye(4, dtype=bool)),
         r"H, W, C >= 1, got shape \(2, 4, 4, 0\)"),
        ((np.ones((4, 4, 3), np.float32), np.ones((4, 4, 3), np.float32), np.eye(4, dtype=bool)),
         r"components must be a float array \(K, H, W, C\)"),
        ((np.ones((2, 4, 4, 3), np.float32), np.ones((4, 3), np.float32), np.eye(4, dtype=bool)),
         r"unreached must be a float array of shape \(4, 4, 3\)"),
        ((np.ones((2, 4, 4, 3), np.float32), np.ones((4, 4, 3), np.float32), np.eye(4)), "target must be a bool array"),
        ((np.ones((2, 4, 4, 3), np.int32), np.ones((4, 4, 3), np.float32), np.eye(4, dtype=bool)),
         "components must be a float array"),
        ((np.ones((9, 1, 1, 3), np.float32), np.ones((1, 1, 3), np.float32), np.ones((1, 1), bool)),
         "K in 1..8"),
    ],
    ids=["0-channel", "3-d", "unreached", "target", "int", "order-9"],
)
def test_hand_built_decompositions_are_checked_when_built(tally, arrays, match):
    tally.injected += 1
    with pytest.raises(InputError, match=match):
        Decomposition(*arrays)


def test_gray_code_with_an_infinite_projector_resolution_is_refused(tally):
    from engine.calibrate import decode_gray_code

    tally.injected += 1
    with pytest.raises(InputError, match="projector_resolution must be two positive integers"):
        decode_gray_code([np.zeros((4, 4, 3), np.float32)] * 4, (float("inf"), 4))


# ----------------------------------------------------------------------------- 15: read-only sessions


def test_recolor_of_a_read_only_session_writes_its_image_warns_and_succeeds(captured, tmp_path, albedit, tally,
                                                                               monkeypatch):
    real_open = os.open
    inside = str(captured.resolve())

    def read_only(path, flags, *args, **kwargs):  # the folder is on a read-only medium (tests run as root)
        if str(os.path.realpath(path)).startswith(inside) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", read_only)
    before = (captured / "manifest.json").read_bytes()
    tally.injected += 1
    rc, lines = albedit("recolor", captured, "--kappa", "3,0.5,1", "-o", tmp_path / "out.exr")
    assert rc == 0 and read_image(tmp_path / "out.exr").shape == (16, 16, 3)
    assert "the edit was not saved in the session" in lines[-1] and "read-only" in lines[-1]
    assert (captured / "manifest.json").read_bytes() == before
    monkeypatch.undo()
    expected = recolor_trusted(load_trusted(Session.open(captured)), (3, 0.5, 1)).image  # the default recolor
    np.testing.assert_allclose(read_image(tmp_path / "out.exr"), expected, rtol=1e-6)
