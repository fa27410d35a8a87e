"""Suite-wide options: hardware tests (``*_with_device``) run only with ``--device NAME``.

``pytest tests --device gphoto2`` runs them against the named rig (any ``devices.open_rig``
name); without it they are skipped. ``--without-vendor-libraries`` runs the tests as on a
machine without the optional camera libraries (python-gphoto2, harvesters, genicam), even
where they are installed: CI runs the device tests both ways. Registered here, at the root of
the tests, so the options exist however pytest is started (``make test`` starts it on several
folders).
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
        help="rig name for hardware tests (e.g. gphoto2, opencv:0, hotfolder:/path); "
             "without it *_with_device tests are skipped",
    )
    parser.addoption(
        "--without-vendor-libraries",
        action="store_true",
        default=False,
        help="make the optional camera libraries (gphoto2, harvesters, genicam) unimportable, as if not installed",
    )


def pytest_configure(config):
    if config.getoption("--without-vendor-libraries"):
        import sys

        from tests.standins import VENDOR_LIBRARIES, ModuleBlocker

        loaded = [m for m in sys.modules if m.partition(".")[0] in VENDOR_LIBRARIES]
        if loaded:
            raise pytest.UsageError(f"--without-vendor-libraries: {loaded[0]} was imported before the tests started")
        sys.meta_path.insert(0, ModuleBlocker(VENDOR_LIBRARIES))


def pytest_collection_modifyitems(config, items):
    if config.getoption("--device"):
        return
    skip = pytest.mark.skip(reason="hardware test: give --device NAME to run it")
    for item in items:
        name = getattr(item, "originalname", item.name)
        if (name.endswith("_with_device") or item.path.stem.endswith("_with_device")
                or item.get_closest_marker("device")):
            item.add_marker(skip)
