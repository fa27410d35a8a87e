"""What a session's safety costs: storing a capture read back and checked, against a plain atomic write.

``Session.add_capture`` writes the EXR under a temporary name, flushes it, reads it back and
compares every pixel and its record before it gets its name, checksums it, and updates the
manifest under the session's lock. The obvious alternative writes the same EXR atomically
and trusts it. Also: opening a session of N captures (each file's size, header and own
record checked) against reading its manifest alone.

Run: .venv/bin/python bench/session.py [--megapixels 8] [--captures 40]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from engine import imageio
from engine.session import Session


def best_of(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--megapixels", type=float, default=8.0)
    parser.add_argument("--captures", type=int, default=40, help="captures of the session opened")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    h = max(4, int(np.sqrt(args.megapixels * 1e6 * 2 / 3)))
    w = max(4, int(args.megapixels * 1e6 / h))
    image = np.random.default_rng(0).random((h, w, 3), dtype=np.float32)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        session = Session.create(root / "s", rig_name="bench", camera_resolution=(h, w), projector_resolution=(8, 8))
        count = iter(range(10**6))
        ours = best_of(lambda: session.add_capture(f"c{next(count)}", image, pattern_id="p"), args.repeat)
        plain = root / "plain"
        plain.mkdir()

        def trusting():
            imageio.write_image(plain / f"c{next(count)}.exr", image, dtype="float", mode=0o444, exclusive=True)

        checked = imageio._check_written
        imageio._check_written = lambda *_: None  # the same atomic write, without reading it back
        try:
            ref = best_of(trusting, args.repeat)
        finally:
            imageio._check_written = checked
        print(f"store a {h}x{w} capture: checked {ours * 1e3:.0f} ms, trusted {ref * 1e3:.0f} ms "
              f"({ours / ref:.2f}x)")

        small = Session.create(root / "many", rig_name="bench", camera_resolution=(64, 96),
                               projector_resolution=(8, 8))
        tile = np.ones((64, 96, 3), np.float32)
        for i in range(args.captures):
            small.add_capture(f"c{i}", tile * i, pattern_id=f"p{i}")
        opened = best_of(lambda: Session.open(root / "many"), args.repeat)
        manifest = best_of(lambda: json.loads((root / "many" / "manifest.json").read_text()), args.repeat)
        print(f"open a session of {args.captures} captures: {opened * 1e3:.1f} ms "
              f"(its manifest alone {manifest * 1e3:.2f} ms)")


if __name__ == "__main__":
    main()
