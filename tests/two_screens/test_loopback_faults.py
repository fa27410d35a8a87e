"""Faults of the loopback bench, through ``albedit calibrate``: a frame that never arrives, a
half-written file, a file for the wrong pattern (the camera fired twice) and the projector window
closed mid-run each end the run with one plain line, keep every capture taken, and a run after
the fault resumes."""

from __future__ import annotations

import re

import pytest

from engine.session import Session
from tests.two_screens.bench import SCENE, add_rig_options, run_cli


@pytest.fixture
def rig_options(monkeypatch, cache):
    return add_rig_options(monkeypatch, cache)


ERROR = "albedit calibrate: error: "


@pytest.mark.parametrize(
    "fault, options, message",
    [
        # timeouts well above a loaded machine's frame time (1 s once timed out on the first frame under load)
        ("drop", {"timeout": 6.0}, r"no new image arrived in hot folder '.*' within 6 s after running \["),
        ("partial", {"timeout": 8.0, "quiet": 0.3},
         r"hot-folder file 'IMG_0003.tif' \(\d+ bytes, unchanged for 0.\d s\) cannot be read: "),
        ("twice", {}, r"hot folder '.*' received 'IMG_0003b.tif' before the camera was triggered: a frame taken"),
        ("close", {}, r"the projector window on 'HDMI-1' was closed \(by the user or the window manager\)"),
    ],
)
def test_bench_faults_end_in_one_plain_line(tmp_path, capsys, rig_options, fault, options, message):
    session = tmp_path / "session"
    rig_options["loopback"].update(options, faults={3: fault})
    status, lines = run_cli(capsys, "calibrate", session, "--rig", f"loopback:{SCENE}")
    assert status == 1 and re.match(ERROR + message, lines[-1]), lines  # a line of its own, after the bar
    kept = [c.name for c in Session.open(session).captures]
    assert kept[:2] == ["cal-black", "cal-white"] and "cal-xor-001" not in kept  # nothing taken is lost
    if fault == "drop":  # run again: the captures taken are reused, the calibration completes
        del rig_options["loopback"]["faults"]
        status, lines = run_cli(capsys, "calibrate", session, "--rig", f"loopback:{SCENE}")
        assert status == 0 and any(line.startswith(f"calibrated loopback:{SCENE} into") for line in lines), lines
