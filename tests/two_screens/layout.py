"""Screen layouts of Qt's offscreen platform for the tests that need a real second screen.

One process has one Qt platform, fixed when its QApplication starts, so these tests run in a
child pytest process started by tests/devices/test_two_screens.py with
``QT_QPA_PLATFORM="offscreen:configfile=screens.json"`` and ``ALBEDIT_SCREEN_LAYOUT=NAME``; in the
main test run they are not collected.
"""

from __future__ import annotations

from pathlib import Path

from devices.loopback import OFFSCREEN_SCREENS, offscreen_platform

PANEL, PROJECTOR = OFFSCREEN_SCREENS

#: name -> the screens; HDMI-1 is the projector, 1024x768 device pixels
LAYOUTS = {
    "desk": OFFSCREEN_SCREENS,  # a laptop panel and a projector beside it (the loopback bench's)
    "hidpi": [PANEL, {**PROJECTOR, "logicalDpi": 192}],  # the projector at 200 %: 512x384 logical, ratio 2
}

#: the environment variable naming the layout a child process runs on
VARIABLE = "ALBEDIT_SCREEN_LAYOUT"


def platform(folder: Path, name: str) -> str:
    """Write layout ``name`` into ``folder`` and return the ``QT_QPA_PLATFORM`` value for it."""
    return offscreen_platform(folder, LAYOUTS[name])
