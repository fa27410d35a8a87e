"""Fill by similar colour: how much of each target surface one click at the default tolerance takes, and what it
takes beyond it, against the obvious alternative (every pixel compared with the seed alone, what the app did
before); then the cost of a click.

Each target of the virtual scenes is clicked at its deepest pixel (farthest from its edge), on the camera's
photograph (ideal: noise-free; realistic: the noisy camera), under the scene's natural light. A target that
spans several faces (the Cornell box's short box, the wedge's union) cannot be one fill; the multi-coloured
checker and textured targets are left out.

Run: nice .venv/bin/python bench/fill.py [--size 256]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

import devices  # noqa: E402
from app.model.painting import _log_image, _similar_from_log  # noqa: E402

TOLERANCE = 0.1  # the app's default
SCENES = ("cornell", "wedge", "three", "floor")


def seed_only(image: np.ndarray, x: int, y: int, tolerance: float) -> np.ndarray:
    """The alternative: 4-connected pixels within ``tolerance`` (log colour) of the seed pixel itself."""
    log = _log_image(image)[0]
    mask = np.zeros((image.shape[0] + 2, image.shape[1] + 2), np.uint8)
    flags = 4 | cv2.FLOODFILL_MASK_ONLY | cv2.FLOODFILL_FIXED_RANGE | (1 << 8)
    cv2.floodFill(log, mask, (x, y), (0, 0, 0), (tolerance,) * 3, (tolerance,) * 3, flags)
    return mask[1:-1, 1:-1].astype(bool)


def photograph(rig, scene: str) -> np.ndarray:
    hp, wp = rig.projector.resolution
    lit = scene in ("wedge", "floor")  # lit by the projector alone
    rig.projector.show(np.full((hp, wp, 3), 1.0 if lit else 0.0, np.float32))
    return rig.camera.capture().image


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    args = parser.parse_args()
    print("| scene | camera | target | this fill: of the target / beyond it | seed only: of the target / beyond |")
    print("|---|---|---|---|---|")
    for scene in SCENES:
        for ideal in (True, False):
            with devices.open_rig(f"virtual:{scene}", ideal=ideal, resolution=(args.size, args.size), seed=0) as rig:
                image = photograph(rig, scene)
                logs = _log_image(image)
                for name, mask in rig.targets.items():
                    depth = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5)
                    y, x = np.unravel_index(int(np.argmax(depth)), mask.shape)
                    new = _similar_from_log(logs, x + 0.5, y + 0.5, TOLERANCE)
                    old = seed_only(image, int(x), int(y), TOLERANCE)
                    share = [f"{100 * (r & mask).sum() / mask.sum():.0f} % / {int((r & ~mask).sum())} px"
                             for r in (new, old)]
                    print(f"| {scene} | {'ideal' if ideal else 'realistic'} | {name} | {share[0]} | {share[1]} |")
    yy, xx = np.mgrid[0:2048, 0:2048].astype(np.float32)
    wall = np.repeat((0.2 + 0.1 * np.sin(xx / 400) * np.cos(yy / 300))[..., None], 3, axis=2)
    logs = _log_image(wall)
    times, alt = [], []
    for _ in range(5):
        t = time.perf_counter()
        region = _similar_from_log(logs, 100, 100, TOLERANCE)
        times.append(time.perf_counter() - t)
        t = time.perf_counter()
        seed_only(wall, 100, 100, TOLERANCE)
        alt.append(time.perf_counter() - t)
    print(f"\nA click on a shaded 2048² wall: {1000 * np.median(times):.0f} ms, {100 * region.mean():.0f} % of it "
          f"(seed only: {1000 * np.median(alt):.0f} ms with its log image, "
          f"{100 * seed_only(wall, 100, 100, TOLERANCE).mean():.0f} % of it; ratio "
          f"{np.median(times) / np.median(alt):.1f}×)")


if __name__ == "__main__":
    main()
