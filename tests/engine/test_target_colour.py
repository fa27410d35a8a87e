"""engine.target_colour: every colour request becomes κ the same way, impossible ones are refused."""

from __future__ import annotations

import numpy as np
import pytest

from engine.colour import luminance_weights
from engine.decompose import Decomposition
from engine.errors import InputError
from engine.target_colour import NO_REFERENCE, TargetColour


def _decomposition(direct_light, bounce=0.05, shape=(4, 6)):
    """A target on the left half lit by ``direct_light`` (its R^0 L_d), one weak interaction."""
    comps = np.zeros((2, *shape, 3), np.float32)
    target = np.zeros(shape, bool)
    target[:, : shape[1] // 2] = True
    comps[0][target] = direct_light
    comps[1][target] = np.asarray(direct_light) * bounce
    return Decomposition(comps, np.zeros((*shape, 3), np.float32), target)


def _direct(value, shape=(4, 6)):
    d = np.zeros((*shape, 3), np.float32)
    d[:, : shape[1] // 2] = value
    return d


def test_a_colour_is_the_paints_colour_white_balanced_by_d():
    """A warm light on a grey wall: the photograph shows it orange, D (white projector) grey;
    'make it #808080-ish grey' changes nothing but brightness."""
    wall = TargetColour(_decomposition([0.6, 0.4, 0.2]), direct=_direct([0.3, 0.3, 0.3]))
    np.testing.assert_allclose(wall.current / wall.current[0], [1, 1, 1])
    assert float(wall.current @ luminance_weights()) == pytest.approx(float(wall.seen @ luminance_weights()))
    kappa = wall.for_colour(wall.current * 2)
    np.testing.assert_allclose(kappa, [2, 2, 2])
    np.testing.assert_allclose(wall.colour(kappa), wall.current * 2)
    # a colour seen in the photograph is compared with what the photograph shows
    np.testing.assert_allclose(wall.for_seen([0.6, 0.4, 0.2]), [1, 1, 1])


def test_keeping_luminance_changes_hue_only():
    wall = TargetColour(_decomposition([0.2, 0.6, 0.2]))
    kappa = wall.for_colour([0.8, 0.1, 0.1], keep_luminance=True)
    assert float(wall.colour(kappa) @ luminance_weights()) == pytest.approx(float(wall.current @ luminance_weights()))


def test_albedo_requests_need_a_reference_and_stay_below_one():
    relative = TargetColour(_decomposition([0.1, 0.8, 0.1]))
    assert relative.new_albedo([2, 2, 2]) is None
    with pytest.raises(InputError, match=f"cannot ask for an absolute albedo: {NO_REFERENCE}"):
        relative.for_albedo([0.2, 0.1, 0.8])
    wall = TargetColour(_decomposition([0.1, 0.8, 0.1], bounce=0.001), albedo=[0.1, 0.8, 0.1])
    np.testing.assert_allclose(wall.for_albedo([0.2, 0.1, 0.8]), [2, 0.125, 8])
    np.testing.assert_allclose(wall.new_albedo([2, 0.125, 8]), [0.2, 0.1, 0.8])
    np.testing.assert_allclose(wall.ceiling(), [10, 1.25, 10])
    with pytest.raises(InputError, match=r"albedo of 1 or more \(G = 1\).*impossible"):
        wall.for_albedo([0.2, 1.0, 0.5])
    with pytest.raises(InputError, match=r"albedo of 1 or more \(G = 1.2\): impossible.*below \[10.0, 1.25, 10.0\]"):
        wall.check([1, 1.5, 1])
    assert wall.check([2, 0.125, 8]) == ""


def test_a_recolor_the_captured_order_cannot_follow_is_warned():
    wall = TargetColour(_decomposition([0.1, 0.8, 0.1], bounce=0.2))
    assert "has not converged at order 2" in wall.check([1, 1.5, 1])
    assert wall.check([1, 1.05, 1]) == ""  # the same last term, a small change: 0.2 % of the light missed
    assert wall.check([1, 1, 1]) == ""  # κ = 1 is the photograph whatever the order
    assert "diverges" in wall.check([1, 1, 8])
    assert wall.check([0.05, 0.05, 0.05]) == ""


def test_matching_another_target():
    floor = TargetColour(_decomposition([0.2, 0.2, 0.2]), direct=_direct([0.2, 0.4, 0.1]))
    chair = TargetColour(None, direct=_direct([0.4, 0.4, 0.4]))
    # relative: the ratio of the direct images (the paper's Fig. 7)
    np.testing.assert_allclose(floor.to_match(chair), [2, 1, 4], rtol=1e-6)
    # absolute: the ratio of the albedos, whatever the light on each
    floor_abs = TargetColour(floor.decomposition, direct=floor.direct, albedo=[0.2, 0.4, 0.1])
    chair_abs = TargetColour(None, direct=chair.direct, albedo=[0.3, 0.3, 0.3])
    np.testing.assert_allclose(floor_abs.to_match(chair_abs), [1.5, 0.75, 3])
    kept = floor_abs.to_match(chair_abs, keep_luminance=True)
    assert float(floor.colour(kept) @ luminance_weights()) == pytest.approx(float(floor.current @ luminance_weights()))
    with pytest.raises(InputError, match="needs both targets' direct images D"):
        TargetColour(floor.decomposition).to_match(chair)
    with pytest.raises(InputError, match="was not acquired"):
        chair.current  # noqa: B018


@pytest.mark.parametrize("albedo", [[0.1, 0.2], [0.1, -0.2, 0.3], [np.nan, 0.1, 0.1]])
def test_a_malformed_albedo_is_refused(albedo):
    with pytest.raises(InputError, match="albedo must be 3 positive numbers"):
        TargetColour(None, albedo=albedo)
