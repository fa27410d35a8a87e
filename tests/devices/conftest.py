"""Device-test options: hardware tests (``*_with_device`` tests) run only with ``--device NAME``.

``pytest tests/devices --device gphoto2`` runs them against the named rig (any
``devices.open_rig`` name); without it they are skipped. Qt runs offscreen.
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


def _device_option(config) -> str | None:
    try:
        return config.getoption("--device")
    except ValueError:  # the option is only registered when this conftest loads at start-up
        return None


def pytest_collection_modifyitems(config, items):
    if _device_option(config):
        return
    skip = pytest.mark.skip(reason="hardware test: give --device NAME to run it")
    for item in items:
        name = item.originalname if hasattr(item, "originalname") else item.name
        if name.endswith("_with_device") or item.path.stem.endswith("_with_device") or item.get_closest_marker("device"):
            item.add_marker(skip)


@pytest.fixture
def device_name(request) -> str:
    """The rig name given with ``--device`` (tests using it are skipped without it)."""
    name = _device_option(request.config)
    if not name:
        pytest.skip("hardware test: give --device NAME to run it")
    return name
