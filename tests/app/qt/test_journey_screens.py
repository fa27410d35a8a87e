"""J5, screens: the main window and the calibration wizard fit a 1366×768 laptop and a 2× scaled
2880×1800 display — every control reachable, no text cut off (defect 11).

Each screen is a child process (a Qt platform's screens are fixed when it starts):
``tests/app/qt/screen_fit.py`` opens the window with the acquisition dock and walks the
wizard, and reports what does not fit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

SCREENS = {
    "laptop 1366×768": ({"width": 1366, "height": 768}, "1"),
    "2880×1800 at 2×": ({"width": 2880, "height": 1800}, "2"),
}


@pytest.mark.parametrize("name", list(SCREENS))
def test_windows_fit_the_screen(tmp_path, name):
    size, scale = SCREENS[name]
    config = tmp_path / "screens.json"
    config.write_text(json.dumps({"screens": [dict(name="screen", x=0, y=0, logicalDpi=96, logicalBaseDpi=96,
                                                   dpr=1, **size)]}))
    env = dict(os.environ, QT_QPA_PLATFORM=f"offscreen:configfile={config}", QT_SCALE_FACTOR=scale,
               HOME=str(tmp_path), XDG_CONFIG_HOME=str(tmp_path / "config"), XDG_CACHE_HOME=str(tmp_path / "cache"))
    out = tmp_path / "fit.json"
    run = subprocess.run([sys.executable, "-m", "tests.app.qt.screen_fit", str(out)], env=env, cwd=os.getcwd(),
                         capture_output=True, text=True, timeout=240)
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads(out.read_text())
    logical = (size["width"] // int(scale), size["height"] // int(scale))
    assert tuple(result["geometry"]["screen"][2:]) == logical and result["geometry"]["dpr"] == float(scale)
    assert result["problems"] == []
