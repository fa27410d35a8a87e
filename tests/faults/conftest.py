"""The fault suite's tools: a small virtual rig, a disk that fills up, the command line run in-process, a tally.

Every test here injects a fault and proves the promise of a session: nothing finished is lost,
a rerun resumes, a wrong result is never returned silently, and bad input gets one line that
names what was wrong — never a traceback. The tally adds up, over the whole run, the faults
injected, the runs that resumed, the refusals, and the captures lost (always 0); pytest
prints it at the end.
"""

from __future__ import annotations

import errno
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from engine import imageio

RES = (16, 16)


@dataclass
class Tally:
    injected: int = 0
    resumed: int = 0
    refused: int = 0
    lost: int = 0


TALLY = Tally()


@pytest.fixture
def tally() -> Tally:
    """The suite's counters (see the module docstring)."""
    return TALLY


def pytest_terminal_summary(terminalreporter):
    if TALLY.injected:
        terminalreporter.write_line(
            f"fault suite: {TALLY.injected} faults injected, {TALLY.resumed} runs resumed, "
            f"{TALLY.refused} refused with one line, {TALLY.lost} finished captures lost")


@pytest.fixture(scope="session")
def rig_cache(tmp_path_factory) -> Path:
    """One virtual-rig set-up cache for the suite."""
    return tmp_path_factory.mktemp("virtual-cache")


@pytest.fixture
def open_rig(rig_cache):
    """Factory: a small virtual Cornell box (16×16 camera, 8×8 projector); closed after the test."""
    import devices

    rigs = []

    def make(**options):
        options = {"resolution": RES, "projector_resolution": (8, 8), "seed": 3, "patch_size": 0.3,
                   "cache_dir": str(rig_cache), **options}
        rig = devices.open_rig("virtual:cornell", **options)
        rigs.append(rig)
        return rig

    yield make
    for rig in rigs:
        rig.close()


@pytest.fixture(scope="session")
def captured_template(tmp_path_factory, rig_cache) -> Path:
    """A calibrated and captured session (the right wall, order 2) with a saved edit; copy it, don't change it."""
    import devices
    from engine.acquire import CaptureSettings
    from engine.workflow import edit_from_plan, open_session_for_rig, run_calibration, run_capture, save_edit

    path = tmp_path_factory.mktemp("captured") / "s"
    with devices.open_rig("virtual:cornell", resolution=RES, projector_resolution=(8, 8), seed=3, patch_size=0.3,
                          cache_dir=str(rig_cache)) as rig:
        session = open_session_for_rig(path, rig)
        run_calibration(rig, session, levels=5)
        run_capture(rig, session, [("right_wall", rig.targets["right_wall"])], 2,
                    settings=CaptureSettings(per_channel=False))
        save_edit(session, edit_from_plan(session, (2.0, 0.5, 1.5)))
    return path


@pytest.fixture
def captured(captured_template, tmp_path) -> Path:
    """A fresh copy of :func:`captured_template` for one test."""
    shutil.copytree(captured_template, tmp_path / "captured", symlinks=True)
    return tmp_path / "captured"


class FakeDisk:
    """A disk with ``capacity`` bytes, behind :func:`engine.imageio.atomic_write`.

    Every file an atomic write flushes is counted against the capacity; the write that does
    not fit is truncated to what is left — and either reports ``ENOSPC`` or, like the
    OpenImageIO write the issue measured, reports success (``silent``). ``shutil.disk_usage``
    reports what is left, as on a real full disk. :meth:`free` gives the space back.
    """

    def __init__(self, capacity: int, *, silent: bool) -> None:
        self.capacity, self.used, self.silent, self.full = capacity, 0, silent, False
        self.patch = pytest.MonkeyPatch()
        real_fsync, real_usage = imageio._fsync_file, shutil.disk_usage

        def fsync(path: Path) -> None:
            size = os.path.getsize(path)
            if self.used + size > self.capacity:
                self.full = True
                with open(path, "r+b") as fh:
                    fh.truncate(max(0, self.capacity - self.used))
                self.used = self.capacity
                if not self.silent:
                    raise OSError(errno.ENOSPC, "No space left on device")
            else:
                self.used += size
            real_fsync(path)

        def usage(path):
            real = real_usage(path)
            return type(real)(real.total, real.used, max(0, self.capacity - self.used) if self.full else real.free)

        self.patch.setattr(imageio, "_fsync_file", fsync)
        self.patch.setattr(shutil, "disk_usage", usage)

    def free(self) -> None:
        """Give the disk back its space (the user deleted something)."""
        self.patch.undo()


@pytest.fixture
def fake_disk():
    """Factory: ``fake_disk(capacity, silent=...)`` installs a :class:`FakeDisk`, removed after the test."""
    disks = []

    def make(capacity: int, *, silent: bool = True) -> FakeDisk:
        disks.append(FakeDisk(capacity, silent=silent))
        return disks[-1]

    yield make
    for disk in disks:
        disk.free()


@pytest.fixture
def albedit(capsys):
    """Run ``albedit ARGS`` in this process: ``(exit status, stderr lines)``; a traceback fails the test."""
    from app.cli.main import run_command

    def run(*args) -> tuple[int, list[str]]:
        try:
            rc = run_command([str(a) for a in args])
        except SystemExit as exc:  # argparse: usage and one error line
            rc = int(exc.code or 0)
        err = capsys.readouterr().err
        assert "Traceback" not in err
        return rc, [line for line in err.replace("\r", "\n").splitlines() if line.strip()]

    return run


def refused(albedit, tally, *args, match: str) -> str:
    """Run a command that must fail with one line naming the problem; returns that line."""
    rc, lines = albedit(*args)
    assert rc != 0, lines
    assert lines and match in lines[-1], lines
    tally.refused += 1
    return lines[-1]


def captures_of(path: Path) -> dict[str, str]:
    """``{capture name: checksum}`` of the session at ``path``, from its manifest."""
    import json

    return {c["name"]: c["sha256"] for c in json.loads((path / "manifest.json").read_text())["captures"]}


def same_decomposition(a, b) -> bool:
    return all(np.array_equal(getattr(a, n), getattr(b, n)) for n in ("components", "unreached", "target"))
