"""End to end on a tiny simulated rig: response → Gray code → footprint → D → re-emission.

Checks that the conventions fit together: re-emitting ``(I ∩ A) / D`` through the warp and the
inverse response makes the camera see ``I`` on the target (paper Sec. 3.3), once the capture
with the projector at black is subtracted.
"""

from __future__ import annotations

import numpy as np

from engine.calibrate import (
    decode_gray_code,
    direct_image,
    fit_response,
    gray_code_patterns,
    high_frequency_patterns,
    projector_footprint,
    ramp_levels,
    response_patterns,
    warp_to_projector,
)

CAM = (48, 64)
PROJ = (64, 90)
GAMMA, BLACK = 2.2, 0.03


class Rig:
    """Offset projector, Lambertian scene with direct light only, gamma projector, ambient."""

    def __init__(self, seed=0):
        rng = np.random.default_rng(seed)
        v, u = np.indices(CAM)
        self.x = np.floor(6 + 1.2 * u + 0.05 * v + 0.5).astype(int)
        self.y = np.floor(4 + 1.15 * v + 0.5).astype(int)
        self.seen = (self.x < PROJ[1]) & (self.y < PROJ[0])
        self.rho = (0.2 + 0.7 * rng.random(CAM + (3,))).astype(np.float32)
        self.ambient = (0.04 * rng.random(CAM + (3,))).astype(np.float32)

    def capture(self, projector_image):
        p = projector_image[np.minimum(self.y, PROJ[0] - 1), np.minimum(self.x, PROJ[1] - 1)]
        light = BLACK + (1 - BLACK) * p.astype(np.float64) ** GAMMA
        light[~self.seen] = 0.0
        return (self.ambient + self.rho * light).astype(np.float32)


def test_reemitting_i_over_d_reproduces_i_on_the_target():
    rig = Rig()
    # 1. projector response, with a projector-off (ambient) capture for the black level
    lv = ramp_levels(17)
    ramp = np.stack([rig.capture(p) for p in response_patterns(lv, PROJ)])
    response = fit_response(ramp, lv, ambient=rig.ambient, mask=rig.seen)
    np.testing.assert_allclose(response.black_level, BLACK, atol=1e-4)
    # 2. correspondences
    caps = [rig.capture(p) for p in gray_code_patterns(PROJ)]
    corr = decode_gray_code(caps, PROJ)
    np.testing.assert_array_equal(corr.valid, rig.seen)
    np.testing.assert_array_equal(corr.x[rig.seen], rig.x[rig.seen])
    # 3. target, its footprint and its direct image
    v, u = np.indices(CAM)
    target = ((v - 22) ** 2 + (u - 30) ** 2 <= 15**2) & corr.valid
    footprint = projector_footprint(corr, target=target)
    hf = np.stack([rig.capture(p) for p in high_frequency_patterns(PROJ, mask_projector=footprint)])
    d = direct_image(hf, black_fraction=response.black_level, ambient=rig.ambient, target=target)
    np.testing.assert_allclose(d.direct[target], rig.rho[target], rtol=1e-4)
    # 4. re-emit a wanted image I on the target
    wanted = np.zeros(CAM + (3,), np.float32)
    wanted[target] = rig.rho[target] * (0.2 + 0.6 * (u[target, None] / CAM[1]))
    per_input = d.per_input
    ratio = np.divide(wanted, per_input, out=np.zeros_like(wanted), where=target[..., None])
    emit = warp_to_projector(ratio, corr, target=target)
    scale = 1.0 / emit.max()  # paper Sec. 6: scale by τ / max, undo after capture
    shown = response.linearize(emit * scale)
    black = rig.capture(np.zeros(PROJ + (3,), np.float32))
    seen = (rig.capture(shown) - black) / scale
    np.testing.assert_allclose(seen[target], wanted[target], rtol=2e-3, atol=1e-4)
    # Off the target, nothing was emitted.
    assert np.abs(seen[~target & corr.valid & (np.hypot(v - 22, u - 30) > 17)]).max() < 1e-5
