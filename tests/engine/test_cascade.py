"""Cascades (Sec. 4, Algorithm 1) and adaptive capture (Sec. 5) on the exact stand-in rig."""

import numpy as np
import pytest

from engine.acquire import Adaptive, Recorder, acquire_cascade
from engine.decompose import decompose
from engine.errors import Cancelled, InputError
from engine.recolor import recolor
from engine.session import Session

from .conftest import H, PatchRig, W, exact_prepared, stand_in_calibration

KAPPAS = [np.array([1.5, 0.6, 2.0]), np.array([0.5, 1.8, 1.2]), np.array([2.0, 2.0, 0.4])]


def _error(image, truth):
    return np.linalg.norm(image - truth) / np.linalg.norm(truth)


def _run(rig, n_targets, order, adaptive=None, recorder=None):
    targets = [(f"t{i}", m) for i, m in enumerate(rig.targets[:n_targets])]
    return acquire_cascade(
        recorder or Recorder(rig),
        stand_in_calibration(rig),
        targets,
        order,
        fixed_kappa=KAPPAS[: n_targets - 1],
        adaptive=adaptive,
        prepared=[exact_prepared(rig, m) for _, m in targets],
    )


@pytest.mark.parametrize("n_targets", [2, 3])
def test_brute_force_cascade_matches_truth_and_costs_k_to_the_t(n_targets):
    rig = PatchRig(seed=1, targets=3)
    order = 4
    result = _run(rig, n_targets, order)
    assert result.images == order**n_targets and result.predicted == 0
    assert result.captures == 1 + (order**n_targets - 1) * 3 == rig.captures
    assert result.fixed_kappa == [k.tolist() for k in KAPPAS[: n_targets - 1]]
    last = rig.targets[n_targets - 1]
    d = decompose(result.acquisition.observations, last)
    for free in (0.5, (1.7, 0.3, 1.1)):
        pairs = [(rig.targets[i], KAPPAS[i]) for i in range(n_targets - 1)] + [(last, np.asarray(free))]
        truth = rig.truth(None, pairs=pairs)
        ours = _error(recolor(d, free), truth)
        assert ours < 2e-3, ours


def test_cascade_beats_recoloring_each_target_separately():
    rig = PatchRig(seed=1, targets=2)
    result = _run(rig, 2, 4)
    d = decompose(result.acquisition.observations, rig.targets[1])
    pairs = [(rig.targets[0], KAPPAS[0]), (rig.targets[1], np.array([2.0, 0.3, 1.0]))]
    truth = rig.truth(None, pairs=pairs)
    ours = _error(recolor(d, (2.0, 0.3, 1.0)), truth)
    # naive (Fig. 8 bottom-left): decompose each target from the photograph alone and add the edits
    photo = rig.truth(1.0)
    naive = photo.copy()
    for mask, kap in pairs:
        sub = acquire_cascade(Recorder(PatchRig(seed=1, targets=2)), stand_in_calibration(rig), [("x", mask)], 4,
                              prepared=[exact_prepared(rig, mask)])
        dd = decompose(sub.acquisition.observations, mask)
        naive += recolor(dd, kap) - photo
    assert ours < 0.1 * _error(naive, truth)


@pytest.mark.parametrize("policy", ["linear", "span"])
def test_adaptive_never_costs_more_and_keeps_its_promise(policy):
    rig = PatchRig(seed=1, targets=3)
    brute = _run(PatchRig(seed=1, targets=3), 3, 4)
    adaptive = _run(rig, 3, 4, Adaptive(policy, 0.01))
    assert adaptive.images + adaptive.predicted == brute.images
    assert adaptive.images < brute.images
    # every prediction made under the "span" policy came with a bound below the threshold
    assert (all(e["bound"] < 0.01 for e in adaptive.log if e["source"] == "predicted" and "bound" in e)
            or policy == "linear")
    pairs = [(rig.targets[0], KAPPAS[0]), (rig.targets[1], KAPPAS[1]), (rig.targets[2], np.array([1.3, 0.7, 1.0]))]
    truth = rig.truth(None, pairs=pairs)
    out_b = recolor(decompose(brute.acquisition.observations, rig.targets[2]), (1.3, 0.7, 1.0))
    out_a = recolor(decompose(adaptive.acquisition.observations, rig.targets[2]), (1.3, 0.7, 1.0))
    assert _error(out_a, truth) < _error(out_b, truth) + 0.01


def test_cascade_resume_after_cancel_gives_the_same_observations(tmp_path):
    rig = PatchRig(seed=2, targets=2)
    session = Session.create(tmp_path / "s", rig_name=rig.name, camera_resolution=(H, W), projector_resolution=(H, W))
    count = {"n": 0}

    def stop():
        count["n"] += 1
        return count["n"] > 20

    with pytest.raises(Cancelled):
        _run(rig, 2, 3, recorder=Recorder(rig, session, should_stop=stop))
    taken = rig.captures
    resumed = _run(rig, 2, 3, recorder=Recorder(rig, Session.open(tmp_path / "s")))
    fresh = _run(PatchRig(seed=2, targets=2), 2, 3)
    np.testing.assert_array_equal(resumed.acquisition.observations, fresh.acquisition.observations)
    assert rig.captures - taken == fresh.captures - taken


def test_bad_cascades_are_refused():
    rig = PatchRig(seed=1, targets=2)
    cal = stand_in_calibration(rig)
    t0, t1 = rig.targets[:2]
    with pytest.raises(InputError, match="every target but the last"):
        acquire_cascade(Recorder(rig), cal, [("a", t0), ("b", t1)], 3)
    with pytest.raises(InputError, match="unique"):
        acquire_cascade(Recorder(rig), cal, [("a", t0), ("a", t1)], 3, fixed_kappa=[1.0])
    with pytest.raises(InputError, match="overlap"):
        acquire_cascade(Recorder(rig), cal, [("a", t0), ("b", t0 | t1)], 3, fixed_kappa=[1.0])
    with pytest.raises(InputError, match="empty"):
        acquire_cascade(Recorder(rig), cal, [], 3)
    with pytest.raises(InputError, match="non-negative"):
        acquire_cascade(Recorder(rig), cal, [("a", t0), ("b", t1)], 3, fixed_kappa=[-1.0])
    soft = t0.astype(np.float32)
    soft[np.nonzero(t0)[0][0], np.nonzero(t0)[1][0]] = 0.5  # one partly covered pixel: a soft edge
    claims = t1.copy()
    claims[soft == 0.5] = True  # b wholly on the pixel a covers half: coverages sum past 1
    with pytest.raises(InputError, match="overlap"):
        acquire_cascade(Recorder(rig), cal, [("a", soft), ("b", claims)], 3, fixed_kappa=[1.0])
    from engine.workflow.capture import check_targets

    check_targets([("a", soft), ("b", t1)], t0.shape)  # any target may be soft, the earlier ones too
    check_targets([("b", t1), ("a", soft)], t0.shape)
    assert rig.captures == 0


def test_automatic_order_stops_when_the_linear_prediction_is_good_enough():
    from engine.acquire import Adaptive

    rig = PatchRig(seed=1)
    cal = stand_in_calibration(rig)
    loose = acquire_cascade(Recorder(rig), cal, [("t", rig.target)], "auto", adaptive=Adaptive("brute", 0.05),
                            prepared=[exact_prepared(rig)])
    tight = acquire_cascade(Recorder(PatchRig(seed=1)), cal, [("t", rig.target)], "auto",
                            adaptive=Adaptive("brute", 1e-4), prepared=[exact_prepared(rig)])
    k_loose, k_tight = len(loose.acquisition.observations), len(tight.acquisition.observations)
    assert 3 <= k_loose < k_tight <= 8
    errors = [e["prediction_error"] for e in loose.log if "prediction_error" in e]
    assert errors[-1] < 0.05 and all(e >= 0.05 for e in errors[:-1])
    with pytest.raises(InputError, match="single target"):
        acquire_cascade(Recorder(rig), cal, [("a", rig.targets[0]), ("b", rig.targets[0])], "auto", fixed_kappa=[1.0])


def test_recolored_observations_are_predicted_and_skip_their_captures():
    rig = PatchRig(seed=1, targets=3)
    result = _run(rig, 3, 4, Adaptive("linear", 0.01))
    levels = {e["level"] for e in result.log if e["source"] == "predicted"}
    assert levels & {1, 2}, levels  # whole recolored sub-decompositions were predicted
    # a prediction at level l stands for the 4**l images its decomposition would have taken
    assert result.images + result.predicted == 4**3
    pairs = [(rig.targets[0], KAPPAS[0]), (rig.targets[1], KAPPAS[1]), (rig.targets[2], np.array([2.0, 2.0, 4.0]))]
    out = recolor(decompose(result.acquisition.observations, rig.targets[2]), (2.0, 2.0, 4.0))
    assert _error(out, rig.truth(None, pairs=pairs)) < 1e-3
