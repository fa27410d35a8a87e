"""Issue 11, items 2 and 3: a creation killed half way is completed; killed writes leave no temporary files."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from engine import imageio
from engine.errors import SessionError
from engine.session import Session
from engine.session.folder import Session as Folder
from engine.workflow import open_session_for_rig, run_calibration

REPO = Path(__file__).resolve().parents[2]


class Killed(BaseException):
    """Stands for the process dying: nothing after it runs, no cleanup but what ``finally`` does."""


def _die_after(monkeypatch, target, attribute, calls: int):
    real = getattr(target, attribute)
    seen = {"n": 0}

    def dying(*args, **kwargs):
        seen["n"] += 1
        if seen["n"] > calls:
            raise Killed
        return real(*args, **kwargs)

    monkeypatch.setattr(target, attribute, dying)


# where a creation can die: after the folder, after each sub-folder, before the manifest
@pytest.mark.parametrize("mkdirs", [0, 1, 2, 3])
def test_a_creation_killed_half_way_is_completed_by_the_next_run(open_rig, tmp_path, monkeypatch, tally, mkdirs):
    rig = open_rig()
    path = tmp_path / "s"
    _die_after(monkeypatch, Path, "mkdir", mkdirs + 1)  # the folder itself, then the four sub-folders
    with pytest.raises(Killed):
        open_session_for_rig(path, rig)
    tally.injected += 1
    monkeypatch.undo()
    assert path.is_dir() and not (path / "manifest.json").exists()
    session = open_session_for_rig(path, rig)
    run_calibration(rig, session, levels=5)
    tally.resumed += 1
    assert Session.open(path, verify=True).has_capture("cal-white")


def test_a_creation_killed_while_writing_the_manifest_is_completed(open_rig, tmp_path, monkeypatch, tally):
    rig = open_rig()
    path = tmp_path / "s"
    monkeypatch.setattr(Folder, "_commit", lambda self, manifest: (_ for _ in ()).throw(Killed()))
    with pytest.raises(Killed):
        open_session_for_rig(path, rig)
    tally.injected += 1
    monkeypatch.undo()
    assert sorted(p.name for p in path.iterdir()) == ["cache", "calibration", "captures", "masks", "session.lock"]
    open_session_for_rig(path, rig)
    tally.resumed += 1


@pytest.mark.parametrize("content", ["photo.jpg", "captures/c.exr", "sub/deeper"])
def test_a_folder_holding_anything_else_is_still_refused(open_rig, tmp_path, content):
    rig = open_rig()
    (tmp_path / "s" / content).parent.mkdir(parents=True, exist_ok=True)
    (tmp_path / "s" / content).write_bytes(b"someone else's")
    with pytest.raises(SessionError, match="the folder is not empty"):
        open_session_for_rig(tmp_path / "s", rig)
    assert (tmp_path / "s" / content).read_bytes() == b"someone else's"


def _kill_during_write(path: Path, script: str) -> None:
    code = textwrap.dedent(f"""
        import os
        from pathlib import Path
        import numpy as np
        from engine import imageio
        from engine.session import Session
        session = Session.open(Path({str(path)!r}))
        real = imageio._fsync_file
        def die(temp):
            real(temp)
            os._exit(17)  # killed with the temporary file complete on disk, before its rename
        imageio._fsync_file = die
    """) + textwrap.dedent(script)
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 17, result.stderr


@pytest.mark.parametrize(
    "write",
    [
        "session.add_capture('c1', np.ones((6, 8, 3), np.float32), pattern_id='p')",
        "session.write_mask('m', np.eye(6, 8, dtype=bool))",
        "session.write_array('rig', 'lut', np.arange(5.0))",
        "session.write_array('rig', 'image', np.ones((6, 8, 3), np.float32))",
        "session.cache_put('k', {'x': np.zeros(3)})",
        "session.update(order=3)",
    ],
    ids=["capture", "mask", "npy", "exr", "cache", "manifest"],
)
def test_temporary_files_of_killed_writes_are_removed_on_open(tmp_path, tally, write):
    path = tmp_path / "s"
    Session.create(path, rig_name="virtual:cornell", camera_resolution=(6, 8), projector_resolution=(4, 4))
    before = sorted(p.relative_to(path) for p in path.rglob("*") if p.is_file())
    _kill_during_write(path, write)
    tally.injected += 1
    temps = [p for p in path.rglob("*") if imageio.is_temp_name(p.name)]
    assert len(temps) == 1
    session = Session.open(path)
    assert session.removed == [temps[0].relative_to(path).as_posix()]
    assert sorted(p.relative_to(path) for p in path.rglob("*") if p.is_file()) == before
    tally.resumed += 1
    assert session.state == {} and not session.captures  # nothing half-done became part of the session
    np.testing.assert_array_equal(session.add_capture("c1", np.ones((6, 8, 3), np.float32), pattern_id="p").shape,
                                  (6, 8, 3))
