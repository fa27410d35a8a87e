"""Screen layouts of Qt's offscreen platform for the tests that need a real second screen.

One process has one Qt platform, fixed when its QApplication starts, so these tests run in a
child pytest process started by tests/devices/test_two_screens.py with
``QT_QPA_PLATFORM="offscreen:configfile=screens.json"`` and ``ALBEDIT_SCREEN_LAYOUT=NAME``; in the
main test run they are not collected.

Qt's offscreen platform adds configured screens in the order of their names and makes the first
one primary, so the laptop panel is named to sort before ``HDMI-1``.
"""

from __future__ import annotations

import json
from pathlib import Path

PANEL = {"name": "Built-in display", "x": 0, "y": 0, "width": 1920, "height": 1080, "logicalDpi": 96, "logicalBaseDpi": 96, "dpr": 1}

#: name -> the offscreen platform's configuration; HDMI-1 is the projector, 1024x768 device pixels
LAYOUTS = {
    # a laptop panel and a projector beside it
    "desk": {"screens": [PANEL, {"name": "HDMI-1", "x": 1920, "y": 0, "width": 1024, "height": 768,
                                 "logicalDpi": 96, "logicalBaseDpi": 96, "dpr": 1}]},
    # the same projector at 200 % scaling: 512x384 logical pixels, device-pixel ratio 2
    "hidpi": {"screens": [PANEL, {"name": "HDMI-1", "x": 1920, "y": 0, "width": 1024, "height": 768,
                                  "logicalDpi": 192, "logicalBaseDpi": 96, "dpr": 1}]},
}

#: the environment variable naming the layout a child process runs on
VARIABLE = "ALBEDIT_SCREEN_LAYOUT"


def platform(folder: Path, name: str) -> str:
    """Write layout ``name`` into ``folder`` and return the ``QT_QPA_PLATFORM`` value for it."""
    path = Path(folder) / f"screens-{name}.json"
    path.write_text(json.dumps(LAYOUTS[name]))
    return f"offscreen:configfile={path}"
