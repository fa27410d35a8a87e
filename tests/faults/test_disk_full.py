"""Issue 11, item 1: the disk fills up during calibrate + capture; nothing is lost and a rerun resumes.

The disk is the suite's :class:`~tests.faults.conftest.FakeDisk`: at every injection point the
write that does not fit is truncated, either silently (as OpenImageIO did) or with ENOSPC.
The run stops with one line saying how much space is free and needed and that rerunning
resumes; after the space is freed the same run completes, every capture finished before the
fault is kept (never retaken), and the decomposition is bit-identical to an uninterrupted
run's — on the realistic (noisy) rig, since each frame's noise is seeded by its identity.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from app.cli._args import report_session
from engine import imageio
from engine.acquire import CaptureSettings
from engine.errors import DiskFull
from engine.session import Session
from engine.workflow import load_decomposition, open_session_for_rig, run_calibration, run_capture
from tests.faults.conftest import captures_of, same_decomposition

SETTINGS = CaptureSettings(per_channel=False)


def _run(rig, path):
    session = open_session_for_rig(path, rig)
    run_calibration(rig, session, levels=5)
    return run_capture(rig, session, [("right_wall", rig.targets["right_wall"])], 2, settings=SETTINGS)


@pytest.fixture(scope="module")
def reference(tmp_path_factory, rig_cache):
    """An uninterrupted run: its decomposition and the bytes it wrote."""
    import devices

    path = tmp_path_factory.mktemp("reference") / "s"
    with devices.open_rig("virtual:cornell", resolution=(16, 16), projector_resolution=(8, 8), seed=3,
                          patch_size=0.3, cache_dir=str(rig_cache)) as rig:
        result = _run(rig, path)
    size = sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return result.decomposition, size


# fractions of the bytes an uninterrupted run writes; the slow sweep tries many more points
QUICK = [0.004, 0.1, 0.35, 0.6, 0.85, 0.97]
SWEEP = [round(f, 3) for f in np.linspace(0.002, 0.99, 60)]


def _fill_then_resume(open_rig, tmp_path, fake_disk, tally, reference, fraction, silent):
    decomposition, size = reference
    rig = open_rig()
    path = tmp_path / "s"
    disk = fake_disk(int(size * fraction), silent=silent)
    try:
        _run(rig, path)
        completed = True
    except DiskFull as exc:
        completed = False
        message = str(exc)
        assert "the disk is full" in message and "MB free" in message and "run the same command again" in message
        assert "\n" not in message
    tally.injected += 1
    assert disk.full or completed
    kept = captures_of(path) if (path / "manifest.json").exists() else {}
    disk.free()
    result = _run(rig, path)
    tally.resumed += not completed
    after = captures_of(path)
    lost = sorted(name for name, sha in kept.items() if after.get(name) != sha)
    tally.lost += len(lost)
    assert not lost
    assert same_decomposition(result.decomposition, decomposition)
    reopened = Session.open(path, verify=True)
    assert same_decomposition(load_decomposition(reopened), decomposition)
    assert not [p for p in path.rglob("*") if imageio.is_temp_name(p.name)]
    assert not reopened.orphans
    return completed


@pytest.mark.parametrize("silent", [True, False], ids=["truncated-silently", "ENOSPC"])
@pytest.mark.parametrize("fraction", QUICK)
def test_a_full_disk_loses_nothing_and_a_rerun_resumes(open_rig, tmp_path, fake_disk, tally, reference, fraction,
                                                       silent):
    _fill_then_resume(open_rig, tmp_path, fake_disk, tally, reference, fraction, silent)


@pytest.mark.slow
@pytest.mark.parametrize("fraction", SWEEP)
def test_a_full_disk_at_any_point_of_a_run(open_rig, tmp_path, fake_disk, tally, reference, fraction):
    _fill_then_resume(open_rig, tmp_path, fake_disk, tally, reference, fraction, silent=True)


def test_an_unreadable_leftover_is_quarantined_and_retaken(open_rig, tmp_path, tally, capsys):
    """A capture file an older version left truncated under its final name (never in the manifest)."""
    rig = open_rig()
    path = tmp_path / "s"
    session = open_session_for_rig(path, rig)
    run_calibration(rig, session, levels=5)
    ramp = path / "captures" / "cal-ramp-003.exr"
    data = ramp.read_bytes()
    manifest = path / "manifest.json"
    entries = json.loads(manifest.read_text())
    entries["captures"] = [c for c in entries["captures"] if c["name"] != "cal-ramp-003"]
    manifest.write_text(json.dumps(entries))
    os.chmod(ramp, 0o644)
    ramp.write_bytes(data[: len(data) // 3])
    tally.injected += 1
    reopened = open_session_for_rig(path, rig)  # adopts orphans: this one cannot be read
    assert [(old, new) for old, new, _ in reopened.quarantined] == [("captures/cal-ramp-003.exr",
                                                                    "quarantine/cal-ramp-003.exr")]
    assert (path / "quarantine" / "cal-ramp-003.exr").read_bytes() == data[: len(data) // 3]
    report_session(reopened, "calibrate")  # never silently: the command line says so
    assert "captures/cal-ramp-003.exr could not be read" in capsys.readouterr().err
    run_calibration(rig, reopened, levels=5)  # retakes it
    tally.resumed += 1
    assert Session.open(path, verify=True).has_capture("cal-ramp-003")
