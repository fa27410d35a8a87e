"""The virtual ColorChecker scene (``resources/scenes/checker.json``), built from its definition.

A 1 m box open towards the camera — red-ish left wall, blue-ish right wall, grey floor, back
wall and ceiling, a ceiling lamp — with a ColorChecker Classic (24 patch quads on a black
card) on the back wall and a painted panel under it, both facing the co-axial projector (an
offset pose beside the camera is there too). Patch albedos are
:func:`engine.checker.reference_reflectances`: the chart's published reflectances integrated
over the virtual camera's channels, so the scene's truth is colour-science's data. Run
``python -m devices.virtual.checker_scene`` to rewrite the JSON after changing this file (a
test checks that they agree).
"""

from __future__ import annotations

import json
import sys

from devices.virtual.scene import SCENE_DIR
from engine.checker import COLUMNS, PATCHES, reference_reflectances

PITCH = 0.12  # patch spacing (m)
SWATCH = 0.10  # patch side (m)
CHART_X0, CHART_TOP = 0.14, 0.93  # top-left corner of the patch area on the back wall
PANEL = (0.3, 0.08, 0.7, 0.38)  # x0, y0, x1, y1 of the target panel on the back wall
PANEL_ALBEDO = [0.55, 0.32, 0.18]


def _front_facing(x0: float, y0: float, x1: float, y1: float, z: float) -> list[list[float]]:
    """Corners of an axis-aligned quad at depth z facing the camera (-z)."""
    return [[x0, y0, z], [x0, y1, z], [x1, y1, z], [x1, y0, z]]


def checker_scene() -> dict:
    """The scene as a JSON-ready dict (see :mod:`devices.virtual.scene` for the format)."""
    rho = reference_reflectances()
    white, grey = [0.75, 0.74, 0.72], [0.5, 0.5, 0.5]
    surfaces = [
        {"name": "floor", "corners": [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]], "albedo": grey},
        {"name": "ceiling", "corners": [[0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]], "albedo": white},
        {"name": "back_wall", "corners": _front_facing(0, 0, 1, 1, 1.0), "albedo": grey},
        {"name": "left_wall", "corners": [[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], "albedo": [0.6, 0.22, 0.15]},
        {"name": "right_wall", "corners": [[1, 0, 0], [1, 0, 1], [1, 1, 1], [1, 1, 0]], "albedo": [0.15, 0.25, 0.6]},
        {"name": "ceiling_light",
         "corners": [[0.35, 0.998, 0.2], [0.65, 0.998, 0.2], [0.65, 0.998, 0.5], [0.35, 0.998, 0.5]],
         "albedo": [0.5, 0.5, 0.5], "emission": [15.0, 14.0, 12.0]},
        {"name": "chart_card", "albedo": [0.03, 0.03, 0.03],
         "corners": _front_facing(CHART_X0 - 0.02, CHART_TOP - 4 * PITCH - 0.01,
                                  CHART_X0 + COLUMNS * PITCH, CHART_TOP + 0.02, 0.9995)},
        {"name": "panel", "corners": _front_facing(*PANEL, 0.999), "albedo": PANEL_ALBEDO},
    ]
    gap = (PITCH - SWATCH) / 2
    for i in range(PATCHES):
        r, c = divmod(i, COLUMNS)
        x0 = CHART_X0 + c * PITCH + gap
        y1 = CHART_TOP - r * PITCH - gap
        surfaces.append({"name": f"patch_{i + 1:02d}",
                         "corners": _front_facing(x0, y1 - SWATCH, x0 + SWATCH, y1, 0.999),
                         "albedo": [float(v) for v in rho[i]]})
    return {
        "name": "checker",
        "description": "A ColorChecker Classic (24 patches, colour-science's reflectances in the virtual camera's "
                       "channels) and an orange panel (albedo (0.55, 0.32, 0.18)) on the back wall of a 1 m box "
                       "with coloured side walls and a ceiling lamp; chart and panel face the co-axial projector.",
        "camera": {"position": [0.5, 0.5, -0.9], "look_at": [0.5, 0.5, 0.5], "up": [0, 1, 0], "fov_deg": 40.0},
        # beside the camera, 25 cm left and 10 cm up: the chart and the panel no longer get equal light
        "projector": {"power": [4.0, 4.0, 4.0],
                      "offset": {"position": [0.25, 0.6, -0.85], "look_at": [0.5, 0.5, 0.5], "up": [0, 1, 0],
                                 "fov_deg": 44.0}},
        "surfaces": surfaces,
        "targets": {
            "panel": [{"surface": "panel"}],
            "checker": [{"surface": f"patch_{i + 1:02d}"} for i in range(PATCHES)],
            "right_wall": [{"surface": "right_wall"}],
        },
        "lighting": {"ambient": True, "projector_flood": 0.0},
        "patch_size": 0.1,
    }


def main() -> int:
    """Write ``resources/scenes/checker.json``."""
    path = SCENE_DIR / "checker.json"
    path.write_text(json.dumps(checker_scene(), indent=1) + "\n", encoding="utf-8")
    print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
