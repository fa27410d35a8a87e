"""Colour requests → κ (engine.colour): parsing, κ, refusals and convergence, on exact data."""

import numpy as np
import pytest

from engine.colour import (
    convergence,
    direct_colour,
    kappa_for_albedo,
    kappa_for_colour,
    kappa_limit,
    luminance_weights,
    parse_colour,
    pick_colour,
    to_hex,
    to_lab,
)
from engine.decompose import Decomposition
from engine.errors import InputError
from engine.figurate import transport_matrix


@pytest.mark.parametrize("text", ["#3355cc", "#35c", "3355cc", "#3355CC"])
def test_hex_forms_decode_to_the_srgb_curve(text):
    lin = parse_colour(text)
    encoded = np.array([0x33, 0x55, 0xCC]) / 255
    expected = np.where(encoded <= 0.04045, encoded / 12.92, ((encoded + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(lin, expected, rtol=1e-6)
    assert to_hex(lin) == "#3355cc"


def test_srgb_lab_and_linear_forms_agree_on_one_colour():
    lin = parse_colour("#3355cc")
    srgb = ",".join(f"{v:.9f}" for v in np.array([0x33, 0x55, 0xCC]) / 255)
    np.testing.assert_allclose(parse_colour(f"srgb:{srgb}"), lin, rtol=1e-6)
    lab = to_lab(lin)
    np.testing.assert_allclose(parse_colour("lab:" + ",".join(f"{v:.9f}" for v in lab)), lin, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(parse_colour("linear: 0.2 0.1 0.8"), [0.2, 0.1, 0.8])


@pytest.mark.parametrize("text, match", [
    ("blue", "cannot read"),
    ("srgb:0,128,255", "0–1"),
    ("lab:50,-120,120", "gamut"),
    ("lab:150,0,0", "L\\*"),
    ("-0.1,0.2,0.3", "≥ 0"),
    ("hsv:1,2,3", "cannot read"),
])
def test_unreadable_or_impossible_colours_are_refused_with_the_fix(text, match):
    with pytest.raises(InputError, match=match):
        parse_colour(text)


def test_eyedropper_averages_linear_light_and_decodes_reference_pictures():
    img = np.zeros((6, 8, 3), np.float32)
    img[:, 4:] = 1.0  # half black, half white: the pick straddles the edge
    assert pick_colour(img, 4, 3, radius=1).tolist() == pytest.approx([2 / 3] * 3)
    encoded = np.full((4, 4, 3), 0x80 / 255, np.float32)  # a reference picture's sRGB grey
    assert pick_colour(encoded, 0, 0, radius=3, encoded=True) == pytest.approx(parse_colour("#808080"))
    with pytest.raises(InputError, match="outside the 8×6 image"):
        pick_colour(img, 8, 0)
    with pytest.raises(InputError, match="radius"):
        pick_colour(img, 1, 1, radius=-1)


def test_kappa_is_the_ratio_and_keeping_luminance_keeps_only_hue():
    current, wanted = np.array([0.1, 0.8, 0.1]), np.array([0.2, 0.1, 0.8])
    np.testing.assert_allclose(kappa_for_colour(current, wanted), [2.0, 0.125, 8.0])
    k = kappa_for_colour(current, wanted, keep_luminance=True)
    new = k * current
    assert new @ luminance_weights() == pytest.approx(current @ luminance_weights())
    np.testing.assert_allclose(new / new.sum(), wanted / wanted.sum())  # the wanted chromaticity
    with pytest.raises(InputError, match="black channel"):
        kappa_for_colour([0.0, 0.5, 0.5], wanted)
    with pytest.raises(InputError, match="no hue"):
        kappa_for_colour(current, [0, 0, 0], keep_luminance=True)


def test_an_albedo_of_one_or_more_is_refused_with_the_reason():
    with pytest.raises(InputError, match=r"G = 1.*impossible.*diverge"):
        kappa_for_albedo([0.1, 0.8, 0.1], [0.2, 1.0, 0.5])
    with pytest.raises(InputError, match="not lit like the target"):
        kappa_for_albedo([0.1, 1.3, 0.1], [0.2, 0.5, 0.5])
    np.testing.assert_allclose(kappa_for_albedo([0.1, 0.8, 0.1], [0.0, 0.4, 0.05]), [0.0, 0.5, 0.5])


def _geometric(ratio, order, *, first=(1.0, 1.0, 1.0)):
    """A one-pixel target whose components fall geometrically: R^i L_d = first * ratio^i."""
    comps = np.zeros((order, 1, 2, 3), np.float64)
    for i in range(order):
        comps[i, 0, 0] = np.asarray(first) * np.asarray(ratio) ** i
    return Decomposition(comps, np.zeros((1, 2, 3)), np.array([[True, False]]))


def test_direct_colour_white_balances_with_the_direct_image():
    d = _geometric(0.3, 3, first=(0.4, 0.3, 0.1))  # a warm light on a neutral surface
    assert direct_colour(d).tolist() == pytest.approx([0.4, 0.3, 0.1])
    flat = np.zeros((1, 2, 3))
    flat[0, 0] = 0.5  # the projector (white) sees it neutral
    balanced = direct_colour(d, direct=flat)
    assert balanced[0] == pytest.approx(balanced[1]) == pytest.approx(balanced[2])
    assert balanced @ luminance_weights() == pytest.approx(np.array([0.4, 0.3, 0.1]) @ luminance_weights())
    with pytest.raises(InputError, match="zero on the whole target"):
        direct_colour(d, direct=np.zeros((1, 2, 3)))


def _measured(modes, order):
    """A one-pixel target decomposed (exactly, Eq. 6) from the observations of an infinite series
    of interactions ``S_n = Σ_j a_j λ_j^n`` per channel: ``obs[r] = Σ_j a_j / (1 − λ_j)^(r+1)``."""
    obs = np.zeros((order, 1, 1, 3))
    for c, channel in enumerate(modes):
        for a, lam in channel:
            obs[:, 0, 0, c] += a / (1 - lam) ** np.arange(1, order + 1)
    inside = np.linalg.solve(transport_matrix(order), obs.reshape(order, -1)).reshape(obs.shape)
    return Decomposition(inside, np.zeros((1, 1, 3)), np.ones((1, 1), bool))


@pytest.mark.parametrize("order", [2, 3, 4, 6])
def test_kappa_limit_is_the_series_growth_not_the_truncated_fits(order):
    """One mode: exact at any order. Two modes: exact from order 4 (Prony), an overestimate of
    the limit below. The ratio of the fit's last two components would be far off."""
    single = _measured([[(1.0, 0.05)], [(1.0, 0.2)], [(1.0, 0.5)]], order)
    np.testing.assert_allclose(kappa_limit(single), [20.0, 5.0, 2.0], rtol=1e-6)
    two = _measured([[(1.0, 0.02), (0.3, 0.17)]] * 3, order)
    limit = kappa_limit(two)
    if order >= 4:
        np.testing.assert_allclose(limit, 1 / 0.17, rtol=1e-6)
    else:
        assert np.all(limit > 1 / 0.17)
    sums = two.components[:, 0, 0, 0]
    if order >= 4:
        assert sums[-2] / sums[-1] < 0.8 / 0.17  # what the last components alone would say


def test_convergence_share_limit_and_advice():
    d = _geometric([0.05, 0.2, 0.5], 4)
    ok = convergence(d, [1.0, 1.0, 0.2])
    assert ok.converged and ok.message() == ""
    slow = convergence(d, [1.0, 1.0, 1.0])
    # B: last term 0.5^3 of 1 + 0.5 + 0.25 + 0.125
    assert slow.share[2] == pytest.approx(0.125 / 1.875)
    assert not slow.converged and "higher order" in slow.message() and "in B" in slow.message()
    diverging = convergence(d, [1.0, 8.0, 1.0])
    assert diverging.ratio[1] == pytest.approx(8.0 / kappa_limit(d)[1]) and diverging.ratio[1] > 1
    assert "diverges in G" in diverging.message() and "smaller change" in diverging.message()


def test_convergence_of_the_virtual_cornell_truth_flags_the_papers_kappa_at_low_order():
    import devices

    with devices.open_rig("virtual:cornell", ideal=True, resolution=(32, 32), cache_dir=False, patch_size=0.2) as rig:
        mask = rig.targets["right_wall"]
        kappa = [2.0, 0.125, 8.0]
        shares = []
        for order in (2, 6):
            t = rig.truth.components(mask, order)
            d = Decomposition.from_components(t.inside, t.outside[: order - 1], t.unreached, mask)
            shares.append(convergence(d, kappa))
        # κ_B = 8 on a 0.1 albedo wall: 10 % of the blue light in the last component at order 2
        assert not shares[0].converged and shares[0].share[2] > 0.02
        assert shares[1].share[2] < shares[0].share[2]
        assert np.all(shares[1].ratio < 1)
