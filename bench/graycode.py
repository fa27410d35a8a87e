"""Gray-code decoding: engine.calibrate.decode_gray_code vs OpenCV's getProjPixel per pixel.

Renders the Gray-code sequence of a 1024×768 projector into a 640×480 uint8 camera through a
smooth warp (with blur and noise), decodes every camera pixel both ways, checks that they
agree wherever both decode, and prints the times and their ratio; then the calibration's XOR
code (which OpenCV cannot decode), rendered and decoded the same way.

Run: .venv/bin/python bench/graycode.py [--camera 480x640] [--projector 768x1024]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.calibrate import decode_gray_code, gray_code_patterns  # noqa: E402


def render(cam, proj, seed=0, code="gray"):
    h, w = cam
    hp, wp = proj
    v, u = np.indices(cam, dtype=np.float32)
    x = (0.05 * wp + 1.35 * u * (wp / 1024) + 0.04 * v + 3 * np.sin(v / 40)).astype(np.float32)
    y = (0.04 * hp + 1.45 * v * (hp / 768) + 0.03 * u).astype(np.float32)
    rng = np.random.default_rng(seed)
    albedo = (0.4 + 0.5 * rng.random(cam)).astype(np.float32)
    out = []
    for img in gray_code_patterns(proj, code=code):
        plane = cv2.remap(img[..., 0], x, y, cv2.INTER_LINEAR, borderValue=0)
        plane = cv2.GaussianBlur(plane, (0, 0), 0.5)
        val = 15 + 220 * albedo * plane + rng.normal(0, 1.5, cam)
        out.append(np.clip(np.round(val), 0, 255).astype(np.uint8))
    return out


def opencv_decode(pats, proj):
    hp, wp = proj
    g = cv2.structured_light.GrayCodePattern.create(wp, hp)
    h, w = pats[0].shape
    x = np.full((h, w), -1, np.int32)
    y = np.full((h, w), -1, np.int32)
    ok = np.zeros((h, w), bool)
    for j in range(h):
        for i in range(w):
            err, (px, py) = g.getProjPixel(pats, i, j)
            if not err:
                ok[j, i], x[j, i], y[j, i] = True, px, py
    return x, y, ok


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--camera", default="480x640", help="camera HxW")
    ap.add_argument("--projector", default="768x1024", help="projector HxW")
    ap.add_argument("--repeat", type=int, default=10)
    a = ap.parse_args()
    cam = tuple(int(s) for s in a.camera.split("x"))
    proj = tuple(int(s) for s in a.projector.split("x"))
    caps = render(cam, proj)
    xor_caps = render(cam, proj, code="xor")
    pats = caps[:-2]
    print(f"camera {cam[1]}×{cam[0]}, projector {proj[1]}×{proj[0]}, {len(pats)} pattern images (uint8)")

    t0 = time.perf_counter()
    x, y, ok = opencv_decode(pats, proj)
    t_cv = time.perf_counter() - t0

    times = []
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        c = decode_gray_code(pats, proj, code="gray")
        times.append(time.perf_counter() - t0)
    t_np = min(times)
    t0 = time.perf_counter()
    cs = decode_gray_code(caps, proj, code="gray")  # with white/black: shadow mask too
    t_shadow = time.perf_counter() - t0
    t0 = time.perf_counter()
    cx = decode_gray_code(xor_caps, proj)
    t_xor = time.perf_counter() - t0

    agree = np.array_equal(c.valid, ok) and np.array_equal(c.x[ok], x[ok]) and np.array_equal(c.y[ok], y[ok])
    print(f"decoded: {ok.mean():.1%} of camera pixels; agreement with OpenCV: {'exact' if agree else 'MISMATCH'}")
    print(f"with shadow mask: {cs.summary()}")
    print(f"XOR code, with shadow mask: {cx.summary()}")
    print()
    print(f"{'method':<44}{'time':>12}{'ratio':>10}")
    print(f"{'OpenCV getProjPixel, one call per pixel':<44}{t_cv * 1e3:>10.1f} ms{1.0:>9.1f}x")
    print(f"{f'decode_gray_code (numpy, best of {a.repeat})':<44}{t_np * 1e3:>10.1f} ms{t_cv / t_np:>9.0f}x")
    print(f"{'decode_gray_code + white/black shadow mask':<44}{t_shadow * 1e3:>10.1f} ms{t_cv / t_shadow:>9.0f}x")
    print(f"{'the same, XOR code':<44}{t_xor * 1e3:>10.1f} ms{t_cv / t_xor:>9.0f}x")
    if not agree:
        raise SystemExit("decoders disagree")


if __name__ == "__main__":
    main()
