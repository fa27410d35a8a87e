"""Single-target acquisition against an exact stand-in rig.

The stand-in is the radiosity scene of test_physics driven by a projector: a co-axial
projector of the camera's resolution adds direct outgoing radiance ``ρ g p`` at each pixel
(``p`` the projector's linear light, after a gamma the calibration knows), the ambient light
is the scene's emitters, and the camera sees every patch. The virtual rig tests in
tests/devices do the same with real geometry.
"""

import numpy as np
import pytest

from engine.acquire import CaptureSettings, PreparedTarget, Recorder, acquire_single
from engine.calibrate import Calibration, Correspondence, ProjectorResponse
from engine.decompose import decompose
from engine.errors import Cancelled, InputError, SessionError
from engine.recolor import recolor
from engine.session import Session

H, W, C = 8, 10, 3
GAMMA = 2.2


class _Frame:
    def __init__(self, image):
        self.image, self.exposure, self.gain, self.black_level = image, 1.0, 1.0, 0.0
        self.saturated = np.zeros(image.shape[:2], bool)
        self.metadata = {}


class PatchRig:
    """Exact co-axial camera-projector stand-in; counts what it was asked to do."""

    name = "patch-rig"

    def __init__(self, seed=0, *, ambient=True):
        rng = np.random.default_rng(seed)
        n = H * W
        self.target = np.zeros((H, W), bool)
        self.target[2:6, 3:7] = True
        t = self.target.ravel()
        g = rng.random((n, n)) ** 3
        g[np.ix_(t, t)] *= 12
        g = (g + g.T) / 2
        np.fill_diagonal(g, 0)
        self.f = g * 0.85 / g.sum(axis=1).max()
        self.albedo = rng.uniform(0.1, 0.8, (n, C))
        self.albedo[t] = rng.uniform(0.05, 0.45, (t.sum(), C))
        self.emission = np.zeros((n, C))
        if ambient:
            lights = rng.choice(np.flatnonzero(~t), 6, replace=False)
            self.emission[lights] = rng.uniform(1.0, 5.0, (6, C))
        self.gain = rng.uniform(0.5, 1.5, n)  # projector irradiance factor per pixel
        self.direct = (self.albedo * self.gain[:, None]).reshape(H, W, C)
        self.camera = self
        self.projector = self
        self.resolution = (H, W)
        self.bit_depth = 8
        self.exposure = 1.0
        self.shown = np.zeros((H, W, C), np.float32)
        self.captures = 0

    def show(self, image):
        assert image.shape == (H, W, 3) and image.min() >= 0 and image.max() <= 1
        self.shown = image

    def capture(self):
        self.captures += 1
        light = self.shown.astype(np.float64) ** GAMMA  # the projector's response
        e = self.emission + (self.direct * light).reshape(-1, C)
        return _Frame(self.solve(self.albedo, e).reshape(H, W, C).astype(np.float32))

    def solve(self, albedo, e):
        n = self.f.shape[0]
        return np.stack([np.linalg.solve(np.eye(n) - albedo[:, c, None] * self.f, e[:, c]) for c in range(C)], 1)

    def truth(self, kappa, *, projector_light=0.0):
        """The scene with the target's albedo scaled, ambient on, the projector at ``projector_light``."""
        a = self.albedo.copy()
        a[self.target.ravel()] *= kappa
        e = self.emission + a * self.gain[:, None] * projector_light
        return self.solve(a, e).reshape(H, W, C)


def _calibration(rig):
    levels = np.linspace(0, 1, 257)
    table = np.repeat((levels**GAMMA)[:, None], 3, axis=1)
    return Calibration(
        rig_name=rig.name,
        camera_resolution=(H, W),
        projector_resolution=(H, W),
        black_frame=np.zeros((H, W, 3), np.float32),
        response=ProjectorResponse(levels, table, np.zeros(3)),
        correspondence=Correspondence.identity((H, W)),
    )


def _prepared(rig):
    t = rig.target
    return PreparedTarget(t.copy(), np.zeros_like(t), np.where(t[:, :, None], rig.direct, 0).astype(np.float32))


@pytest.mark.parametrize("per_channel", [True, False])
@pytest.mark.parametrize("differences", [True, False])
def test_observations_follow_eq_6_and_recolor_matches_truth(per_channel, differences):
    rig = PatchRig()
    settings = CaptureSettings(per_channel=per_channel, differences=differences)
    acq = acquire_single(Recorder(rig), _calibration(rig), rig.target, 6, settings=settings, prepared=_prepared(rig))
    assert acq.observations.shape == (6, H, W, 3)
    assert acq.images == 1 + 5 * (3 if per_channel else 1) == rig.captures
    # I_r = T I_{r-1}: emitting I_{r-1} on the target with the ambient removed (Eq. 5)
    t = rig.target.ravel()
    prev = acq.observations[0].reshape(-1, C).astype(np.float64)
    for r in range(1, 6):
        expected = rig.solve(rig.albedo, np.where(t[:, None], prev, 0))
        np.testing.assert_allclose(acq.observations[r].reshape(-1, C), expected, rtol=2e-4, atol=1e-5 * expected.max())
        prev = expected
    d = decompose(acq.observations, acq.target.mask)
    for kappa in (0.5, 2.0, (2.0, 0.125, 1.5)):
        truth = rig.truth(np.asarray(kappa))
        err = np.linalg.norm(recolor(d, kappa) - truth) / np.linalg.norm(truth)
        assert err < 1e-4, (kappa, err)


def test_session_keeps_captures_and_resume_takes_no_new_ones(tmp_path):
    rig = PatchRig()
    session = Session.create(tmp_path / "s", rig_name=rig.name, camera_resolution=(H, W), projector_resolution=(H, W))
    calib, prepared = _calibration(rig), _prepared(rig)
    calls = {"n": 0}

    def stop_after_seven():
        calls["n"] += 1
        return calls["n"] > 7

    with pytest.raises(Cancelled):
        acquire_single(Recorder(rig, session, should_stop=stop_after_seven), calib, rig.target, 4, prepared=prepared)
    assert rig.captures == 7 and len(Session.open(tmp_path / "s").captures) == 7
    resumed = acquire_single(Recorder(rig, Session.open(tmp_path / "s")), calib, rig.target, 4, prepared=prepared)
    assert rig.captures == 10  # only the 3 missing captures were taken
    fresh = acquire_single(Recorder(PatchRig()), calib, rig.target, 4, prepared=prepared)
    np.testing.assert_array_equal(resumed.observations, fresh.observations)
    again = Recorder(rig, Session.open(tmp_path / "s"))
    acquire_single(again, calib, rig.target, 4, prepared=prepared)
    assert rig.captures == 10 and len(again.reused) == 10 and not again.taken


def test_changed_plan_on_the_same_session_is_refused(tmp_path):
    rig = PatchRig()
    session = Session.create(tmp_path / "s", rig_name=rig.name, camera_resolution=(H, W), projector_resolution=(H, W))
    acquire_single(Recorder(rig, session), _calibration(rig), rig.target, 3, prepared=_prepared(rig))
    with pytest.raises(SessionError, match="different projector pattern"):
        acquire_single(
            Recorder(rig, Session.open(tmp_path / "s")), _calibration(rig), rig.target, 3,
            settings=CaptureSettings(tau=0.5), prepared=_prepared(rig),
        )


def test_photograph_under_projector_flood_uses_a_black_reference():
    rig = PatchRig(ambient=False)  # the only light is the projector (paper Fig. 7-8)
    flood = np.full((H, W, 3), 0.8, np.float32)
    acq = acquire_single(Recorder(rig), _calibration(rig), rig.target, 5, prepared=_prepared(rig), photograph_pattern=flood)
    assert acq.images == 1 + 4 * 3 and rig.captures == acq.images + 1  # + the black reference
    d = decompose(acq.observations, acq.target.mask)
    truth = rig.truth(np.array([1.5, 0.5, 2.0]), projector_light=0.8**GAMMA)
    assert np.linalg.norm(recolor(d, (1.5, 0.5, 2.0)) - truth) / np.linalg.norm(truth) < 1e-3


def test_bad_order_and_foreign_calibration():
    rig = PatchRig()
    with pytest.raises(InputError, match="order"):
        acquire_single(Recorder(rig), _calibration(rig), rig.target, 0)
    other = Calibration(**{**_calibration(rig).__dict__, "rig_name": "virtual:cornell"})
    with pytest.raises(InputError, match="made for rig 'virtual:cornell'"):
        acquire_single(Recorder(rig), other, rig.target, 3)
