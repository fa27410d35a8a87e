"""Canvas overlay cost of a paint stroke: hard brush (binary mask) against feathered brush (coverage).

A brush stroke across a 512² photograph, driven through the app's own path (``Painter`` →
``Document`` → the canvas's mask signal → overlay recomposed in the dab's box → a synchronous
repaint of the canvas). Each sample is one mouse move: the painter's dab, the overlay update
and the repaint. The hard brush keeps the mask binary; the feathered brush (hardness 0) paints
coverage, which the overlay draws with an alpha proportional to it.

Run: QT_QPA_PLATFORM=offscreen nice .venv/bin/python bench/overlay.py [--size 512] [--moves 200]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from PySide6.QtWidgets import QApplication  # noqa: E402

from app.model.document import Document  # noqa: E402
from app.model.painting import Painter, move, press, release  # noqa: E402
from app.qt.canvas import Canvas  # noqa: E402


def stroke_times(size: int, moves: int, hardness: float, brush: float) -> np.ndarray:
    """Seconds per mouse move of one stroke (dab, overlay update, synchronous repaint)."""
    rng = np.random.default_rng(0)
    doc = Document(rng.random((size, size, 3), dtype=np.float32) * 0.5 + 0.25, source="bench")
    t = doc.add_target("wall", np.zeros((size, size), bool))
    doc.add_target("other", np.pad(np.ones((size // 4, size // 4), bool), ((0, 3 * size // 4), (0, 3 * size // 4))))
    doc.set_current(t.uid)
    painter = Painter(doc)
    painter.set_size(brush)
    painter.set_hardness(hardness)
    canvas = Canvas(doc, painter)
    canvas.resize(size, size)
    canvas.show()
    canvas.fit()
    QApplication.processEvents()
    angle = np.linspace(0, 4 * np.pi, moves)
    xs = size / 2 + 0.35 * size * np.cos(angle) * np.linspace(0.3, 1, moves)
    ys = size / 2 + 0.35 * size * np.sin(angle) * np.linspace(0.3, 1, moves)
    painter.handle(press(xs[0], ys[0]))
    out = np.empty(moves - 1)
    for i in range(1, moves):
        t0 = time.perf_counter()
        painter.handle(move(xs[i], ys[i]))
        canvas.repaint()
        out[i - 1] = time.perf_counter() - t0
    painter.handle(release(xs[-1], ys[-1]))
    canvas.close()
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--moves", type=int, default=200)
    parser.add_argument("--brush", type=float, default=40.0, help="brush size in pixels")
    args = parser.parse_args(argv)
    app = QApplication.instance() or QApplication([])
    print(f"paint stroke on a {args.size}² photograph, brush {args.brush:g} px, {args.moves} moves, "
          "per move: dab + overlay + repaint")
    print(f"{'brush':<22} {'p50 ms':>8} {'p95 ms':>8} {'max ms':>8} {'ratio p50':>10}")
    base = None
    for label, hardness in (("hard (binary mask)", 1.0), ("feathered (coverage)", 0.0)):
        stroke_times(args.size, 10, hardness, args.brush)  # warm-up
        s = 1e3 * stroke_times(args.size, args.moves, hardness, args.brush)
        p50 = float(np.median(s))
        base = base or p50
        print(f"{label:<22} {p50:8.2f} {np.percentile(s, 95):8.2f} {s.max():8.2f} {p50 / base:10.2f}", flush=True)
    del app
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
