"""Issue 11, item 4: one advisory lock per session; a second writer is told who holds it; no update is lost."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from engine.errors import SessionError
from engine.session import Session
from engine.session.lock import LOCK_FILE
from tests.faults.conftest import refused

REPO = Path(__file__).resolve().parents[2]
DEADLINE = 60.0


class Holder:
    """Another process holding the session's lock: ``albedit capture`` as far as anyone can tell."""

    def __init__(self, path: Path, tmp: Path, *, die: bool = False) -> None:
        self.ready, self.go = tmp / "ready", tmp / "go"
        end = "os._exit(9)" if die else textwrap.dedent(f"""
            while not Path({str(self.go)!r}).exists() and time.monotonic() < deadline:
                time.sleep(0.01)""")
        code = textwrap.dedent(f"""
            import os, time
            from pathlib import Path
            from engine.session import Session
            deadline = time.monotonic() + {DEADLINE}
            session = Session.open(Path({str(path)!r}))
            with session.writing("albedit capture"):
                session.update(holder="other process")
                Path({str(self.ready)!r}).write_text("held")
        """) + textwrap.indent(end, " " * 4)
        self.process = subprocess.Popen([sys.executable, "-c", code], cwd=REPO)
        deadline = time.monotonic() + DEADLINE
        while not self.ready.exists() and self.process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert self.ready.exists(), "the holder never took the lock"

    def release(self) -> int:
        self.go.write_text("go")
        return self.process.wait(DEADLINE)


def _session(path: Path) -> Session:
    return Session.create(path, rig_name="virtual:cornell", camera_resolution=(6, 8), projector_resolution=(4, 4))


def test_a_second_writer_is_told_who_holds_the_session(tmp_path, tally, monkeypatch):
    from engine.session import lock

    monkeypatch.setattr(lock, "WAIT_SECONDS", 0.2)
    path = tmp_path / "s"
    mine = _session(path)
    holder = Holder(path, tmp_path)
    try:
        tally.injected += 1
        with pytest.raises(SessionError) as exc:
            mine.add_capture("c0", np.ones((6, 8, 3), np.float32), pattern_id="p")
        tally.refused += 1
        message = str(exc.value)
        assert f"is being written by albedit capture (pid {holder.process.pid} on {socket.gethostname()}" in message
        assert "wait until it has finished" in message and "\n" not in message
        assert not (path / "captures" / "c0.exr").exists() and not Session.open(path).captures
        with pytest.raises(SessionError, match="is being written by albedit capture"):
            with mine.writing("a second capture"):
                pass
    finally:
        assert holder.release() == 0
    mine.add_capture("c0", np.ones((6, 8, 3), np.float32), pattern_id="p")  # free again: the write goes through
    state = Session.open(path).state
    assert state == {"holder": "other process"}  # and the holder's update was not lost either


def test_a_lock_left_by_a_killed_process_is_stale_and_taken_over(tmp_path, tally):
    path = tmp_path / "s"
    _session(path)
    holder = Holder(path, tmp_path, die=True)
    assert holder.process.wait(DEADLINE) == 9
    tally.injected += 1
    left = json.loads((path / LOCK_FILE).read_text())
    assert left["pid"] == holder.process.pid  # the file still names the dead holder ...
    session = Session.open(path)
    session.update(order=2)  # ... but the kernel released its lock: taken over at once
    tally.resumed += 1
    assert Session.open(path).state == {"holder": "other process", "order": 2}
    assert (path / LOCK_FILE).read_text() == ""  # released cleanly this time


def test_manifest_updates_read_what_another_writer_committed(tmp_path, tally):
    path = tmp_path / "s"
    stale = _session(path)
    code = textwrap.dedent(f"""
        from pathlib import Path
        import numpy as np
        from engine.session import Session
        s = Session.open(Path({str(path)!r}))
        s.add_capture("theirs", np.zeros((6, 8, 3), np.float32), pattern_id="p")
        s.update(edit_kappa=[2.0, 0.5, 1.0])
    """)
    subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True, timeout=DEADLINE)
    tally.injected += 1
    stale.update(status_note="mine")  # this object read the manifest before the other process wrote it
    stale.add_capture("mine", np.ones((6, 8, 3), np.float32), pattern_id="q")
    reopened = Session.open(path, verify=True)
    assert reopened.state == {"edit_kappa": [2.0, 0.5, 1.0], "status_note": "mine"}
    assert [c.name for c in reopened.captures] == ["theirs", "mine"]


def test_recolor_during_a_capture_writes_its_image_and_says_the_edit_was_not_saved(captured, tmp_path, albedit,
                                                                                   tally, monkeypatch):
    from engine.session import lock

    monkeypatch.setattr(lock, "WAIT_SECONDS", 0.2)
    before = json.loads((captured / "manifest.json").read_text())["state"]["edit"]
    holder = Holder(captured, tmp_path)
    try:
        tally.injected += 1
        rc, lines = albedit("recolor", captured, "--kappa", "3,0.5,1", "-o", tmp_path / "out.exr")
    finally:
        assert holder.release() == 0
    assert rc == 0 and (tmp_path / "out.exr").exists()
    assert "the edit was not saved" in lines[-1] and "is being written by albedit capture" in lines[-1]
    after = Session.open(captured).state
    assert after["edit"] == before and after["holder"] == "other process"  # the capture's write is not overwritten


def test_the_command_line_refuses_a_second_capture(captured, tmp_path, albedit, tally, monkeypatch):
    from engine.session import lock

    monkeypatch.setattr(lock, "WAIT_SECONDS", 0.2)
    kept = (captured / "manifest.json").read_bytes()
    holder = Holder(captured, tmp_path)
    try:
        tally.injected += 1
        refused(albedit, tally, "capture", captured, "--resolution", "16", "--target", "right_wall", "--order", "3",
                match="is being written by albedit capture")
    finally:
        assert holder.release() == 0
    manifest = json.loads((captured / "manifest.json").read_text())
    assert json.loads(kept)["captures"] == manifest["captures"]
    assert sorted(os.listdir(captured / "captures")) == sorted(c["file"].split("/")[1] for c in manifest["captures"])
