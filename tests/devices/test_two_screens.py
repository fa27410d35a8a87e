"""Runs tests/two_screens in child processes on two-screen offscreen layouts.

One process has one Qt platform, fixed when its QApplication starts (this one's has a single
800x800 screen), so the tests that need a laptop panel and a projector beside it run in their
own pytest process per layout and module; a failure here shows the child's report.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.two_screens.layout import VARIABLE, platform

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    "layout, module",
    [
        ("desk", "test_projector_window.py"),
        ("hidpi", "test_projector_window.py"),
        ("desk", "test_loopback.py"),
        ("desk", "test_loopback_faults.py"),
        ("desk", "test_journey.py"),
    ],
)
def test_on_two_screens(tmp_path, layout, module):
    env = dict(os.environ, QT_QPA_PLATFORM=platform(tmp_path, layout), PYTHONPATH=str(ROOT))
    env[VARIABLE] = layout
    args = [sys.executable, "-m", "pytest", f"tests/two_screens/{module}", "-q", "-p", "no:cacheprovider",
            f"--basetemp={tmp_path / 'child'}"]
    out = subprocess.run(args, cwd=ROOT, env=env, capture_output=True, text=True, timeout=280)
    report = "\n".join((out.stdout + out.stderr).strip().splitlines()[-80:])
    assert out.returncode == 0, f"{module} on the {layout!r} layout failed:\n{report}"
    assert " passed" in report and " skipped" not in report, report
