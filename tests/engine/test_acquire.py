"""Single-target acquisition against an exact stand-in rig.

The stand-in is the radiosity scene of test_physics driven by a projector: a co-axial
projector of the camera's resolution adds direct outgoing radiance ``ρ g p`` at each pixel
(``p`` the projector's linear light, after a gamma the calibration knows), the ambient light
is the scene's emitters, and the camera sees every patch. The virtual rig tests in
tests/devices do the same with real geometry.
"""

import numpy as np
import pytest

from engine.acquire import CaptureSettings, Recorder, acquire_single
from engine.calibrate import Calibration
from engine.decompose import decompose
from engine.errors import Cancelled, InputError, SessionError
from engine.recolor import recolor
from engine.session import Session

from .conftest import GAMMA, C, H, PatchRig, W
from .conftest import exact_prepared as _prepared
from .conftest import stand_in_calibration as _calibration


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
    acq = acquire_single(Recorder(rig), _calibration(rig), rig.target, 5, prepared=_prepared(rig),
                         photograph_pattern=flood)
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


class _ClippingRig(PatchRig):
    """A stand-in whose frames clip above 1.0 and whose exposure may be fixed or broken."""

    def __init__(self, *, exposure_error=None, fail_short=False):
        self._exposure_error, self._fail_short = None, fail_short
        self._exp = 1.0
        super().__init__()
        self._exposure_error = exposure_error

    @property
    def exposure(self):
        return self._exp

    @exposure.setter
    def exposure(self, value):
        if self._exposure_error is not None and value != self._exp:
            raise self._exposure_error
        self._exp = value

    def capture(self):
        if self._fail_short and self._exp < 1.0:
            from engine.errors import DeviceError

            raise DeviceError("camera unplugged")
        frame = super().capture()
        frame.saturated = (frame.image * self._exp > 1.0).any(axis=-1)
        return frame


def test_a_camera_that_cannot_change_exposure_keeps_its_clipped_frame():
    from engine.errors import DeviceError

    rig = _ClippingRig(exposure_error=DeviceError("no known exposure unit"))
    rig.shown = np.full((H, W, 3), 1.0, np.float32)
    assert rig.capture().saturated.any()
    rec = Recorder(rig)
    image = rec.capture("clipped", rig.shown)
    assert image.shape == (H, W, 3) and rec.last_saturated.any()


def test_a_capture_failing_inside_a_bracket_is_a_device_fault():
    from engine.errors import DeviceError

    rig = _ClippingRig(fail_short=True)
    with pytest.raises(DeviceError, match="unplugged"):
        Recorder(rig).capture("clipped", np.full((H, W, 3), 1.0, np.float32))
    assert rig.exposure == 1.0  # restored
