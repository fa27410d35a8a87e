"""Tests on a two-screen offscreen layout; collected only in the child process that has it
(see :mod:`tests.two_screens.layout`)."""

from __future__ import annotations

import os

import pytest

from tests.two_screens.layout import LAYOUTS, VARIABLE

LAYOUT = os.environ.get(VARIABLE)
if LAYOUT is None:
    collect_ignore_glob = ["test_*.py"]  # the main run: tests/devices/test_two_screens.py starts them
elif LAYOUT not in LAYOUTS or "configfile=" not in os.environ.get("QT_QPA_PLATFORM", ""):
    raise pytest.UsageError(f"{VARIABLE}={LAYOUT!r} needs QT_QPA_PLATFORM=offscreen:configfile=... of that layout")


@pytest.fixture(scope="session")
def layout() -> dict:
    """The screens this process runs on (the configuration Qt was given)."""
    return {"name": LAYOUT, "screens": LAYOUTS[LAYOUT]}


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One virtual set-up of the bench's scene for every rig of a module (built once, ~10 s)."""
    return tmp_path_factory.mktemp("virtual-cache")
