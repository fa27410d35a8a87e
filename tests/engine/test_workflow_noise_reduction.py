"""A session's noise reduction of a soft mask: the filter runs before the edge blend, as in acquisition."""

import numpy as np

import devices
from engine.denoise import denoise_components
from engine.workflow import load_decomposition, open_session_for_rig, run_calibration, run_capture
from engine.workflow.decomposition import reacquired


def test_a_soft_masks_noise_reduction_filters_before_the_edge_blend(tmp_path):
    with devices.open_rig("virtual:cornell", resolution=(24, 24), seed=2, supersample=2) as rig:
        session = open_session_for_rig(tmp_path / "s", rig)
        run_calibration(rig, session, levels=5)
        run_capture(rig, session, [("right_wall", rig.coverage["right_wall"])], 3)
    measured = load_decomposition(session)
    assert measured.blended is not None and measured.blended.any()  # a soft mask: its edge pixels were blended
    reduced = load_decomposition(session, denoise=2)
    result = reacquired(session)
    target, obs = result.targets[-1][1], result.acquisition.observations
    expected = target.decompose(obs, covariance=result.acquisition.covariance, denoise=2)
    np.testing.assert_array_equal(reduced.components, expected.components)
    np.testing.assert_array_equal(reduced.unreached, expected.unreached)
    # not the blended decomposition filtered (what noise reduction did before)
    after = denoise_components(measured, obs[0], radius=2)
    edge = measured.blended
    assert not np.allclose(reduced.components[:, edge], after.components[:, edge])
