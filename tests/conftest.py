"""Suite-wide options: hardware tests (``*_with_device``) run only with ``--device NAME``.

``pytest tests --device gphoto2`` runs them against the named rig (any ``devices.open_rig``
name); without it they are skipped. Registered here, at the root of the tests, so the
option exists however pytest is started (``make test`` starts it on several folders).
"""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import pytest  # noqa: E402


def pytest_addoption(parser):
    parser.addoption(
        "--device",
        action="store",
        default=None,
        metavar="NAME",
        help="rig name for hardware tests (e.g. gphoto2, opencv:0, hotfolder:/path); without it *_with_device tests are skipped",
    )


def pytest_collection_modifyitems(config, items):
    if config.getoption("--device"):
        return
    skip = pytest.mark.skip(reason="hardware test: give --device NAME to run it")
    for item in items:
        name = getattr(item, "originalname", item.name)
        if name.endswith("_with_device") or item.path.stem.endswith("_with_device") or item.get_closest_marker("device"):
            item.add_marker(skip)
