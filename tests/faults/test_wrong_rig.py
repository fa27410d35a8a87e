"""Issue 11, item 5: a calibration is never used with another set-up of the rig; the refusal says what differs."""

from __future__ import annotations

import pytest

from engine.errors import InputError, SessionError
from engine.session import Session
from engine.workflow import load_compatible_calibration, open_session_for_rig, preflight, run_calibration
from tests.faults.conftest import refused


@pytest.mark.parametrize(
    ("options", "differs"),
    [
        ({"projector": "offset"}, "projector pose 'coaxial' then, 'offset' now"),
        ({"ideal": True}, "ideal False then, True now"),
        ({"patch_size": 0.25}, "patch size 0.3 then, 0.25 now"),
    ],
)
def test_capture_refuses_a_calibration_of_another_set_up(open_rig, tmp_path, tally, options, differs):
    calibrated = open_rig()
    session = open_session_for_rig(tmp_path / "s", calibrated)
    run_calibration(calibrated, session, levels=5)
    other = open_rig(**options)
    before = (tmp_path / "s" / "manifest.json").read_bytes()
    tally.injected += 1
    with pytest.raises(InputError, match="calibration was made with another set-up") as exc:
        preflight(other, Session.open(tmp_path / "s"), [("right_wall", other.targets["right_wall"])], 2)
    assert differs in str(exc.value)
    with pytest.raises(InputError, match=differs):  # reusing the calibration in a new session: refused too
        load_compatible_calibration(tmp_path / "s", other)
    with pytest.raises(SessionError, match=f"recorded with another set-up.*{differs}"):
        open_session_for_rig(tmp_path / "s", other)
    tally.refused += 3
    assert (tmp_path / "s" / "manifest.json").read_bytes() == before


def test_another_scene_content_is_another_set_up(open_rig, tmp_path, tally):
    import json

    from devices.virtual.scene import SCENE_DIR

    calibrated = open_rig()
    run_calibration(calibrated, open_session_for_rig(tmp_path / "s", calibrated), levels=5)
    scene = json.loads((SCENE_DIR / "cornell.json").read_text())
    scene["surfaces"][0]["albedo"] = [0.5, 0.5, 0.5]
    (tmp_path / "cornell.json").write_text(json.dumps(scene))
    import devices

    with devices.open_rig(f"virtual:{tmp_path / 'cornell.json'}", resolution=(16, 16), projector_resolution=(8, 8),
                          patch_size=0.3, cache_dir=False) as edited:
        edited.identity = calibrated.identity  # the same name: only the content differs
        tally.injected += 1
        with pytest.raises(InputError, match="scene '[0-9a-f]{64}' then, '[0-9a-f]{64}' now"):
            load_compatible_calibration(tmp_path / "s", edited)
        tally.refused += 1


def test_the_command_line_refuses_reusing_a_calibration_of_another_set_up(tmp_path, albedit, tally):
    rig = ["--rig", "virtual:cornell", "--resolution", "24"]
    assert albedit("calibrate", tmp_path / "cal", *rig, "--levels", "5")[0] == 0  # realistic
    # options not given are the calibration's (tests/app/cli); one given that differs is refused
    tally.injected += 1
    refused(albedit, tally, "capture", tmp_path / "new", *rig, "--ideal", "--calibration", tmp_path / "cal",
            "--target", "right_wall", "--order", "2", match="ideal False then, True now; recalibrate")
    assert not (tmp_path / "new").exists()
    refused(albedit, tally, "capture", tmp_path / "cal", *rig, "--projector", "offset", "--target", "right_wall",
            "--order", "2", match="projector pose 'coaxial' then, 'offset' now")
