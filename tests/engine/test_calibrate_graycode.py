"""Gray-code patterns and decoding: agreement with OpenCV, accuracy, interreflections, dtypes, bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from engine.calibrate import (
    GRAY_CODES,
    Correspondence,
    PixelStatus,
    decode_gray_code,
    gray_code_bits,
    gray_code_patterns,
)
from engine.errors import InputError

CAM = (96, 128)  # (H, W)
PROJ = (150, 200)  # (Hp, Wp): not powers of two, so codes beyond the projector exist


def true_warp(cam=CAM):
    """Camera pixel centre → continuous projector coordinates (a mild non-affine map)."""
    v, u = np.indices(cam, dtype=np.float64)
    return _warp_at(u, v)


def render(patterns, *, seed=0, noise=1.5, blur=0.6, sub=4, cam=CAM):
    """Render projector patterns into uint8 camera captures through ``true_warp``.

    Each camera pixel integrates ``sub × sub`` samples of the projector image (nearest
    projector pixel), then optical blur, albedo, ambient light, noise and 8-bit quantisation.
    Camera pixels whose warp leaves the projector receive no projector light.
    """
    rng = np.random.default_rng(seed)
    h, w = cam
    hp, wp = patterns.resolution
    offs = (np.arange(sub) + 0.5) / sub - 0.5
    v, u = np.indices(cam, dtype=np.float64)
    samples = []
    for dv in offs:
        for du in offs:
            x, y = _warp_at(u + du, v + dv)
            xi, yi = np.floor(x + 0.5).astype(int), np.floor(y + 0.5).astype(int)
            inside = (xi >= 0) & (xi < wp) & (yi >= 0) & (yi < hp)
            samples.append((np.clip(yi, 0, hp - 1), np.clip(xi, 0, wp - 1), inside))
    albedo = 0.35 + 0.6 * rng.random(cam) ** 0.3
    out = []
    for img in patterns:
        plane = img[..., 0]
        acc = np.zeros(cam)
        for yi, xi, inside in samples:
            acc += np.where(inside, plane[yi, xi], 0.0)
        acc /= len(samples)
        acc = cv2.GaussianBlur(acc, (0, 0), blur)
        val = 12.0 + 220.0 * albedo * acc + rng.normal(0, noise, cam)
        out.append(np.clip(np.round(val), 0, 255).astype(np.uint8))
    return out


def _warp_at(u, v):
    return 12.0 + 1.6 * u + 0.08 * v + 2.0 * np.sin(v / 15.0), 4.0 + 0.05 * u + 1.3 * v


@pytest.fixture(scope="module")
def captures():
    """OpenCV's Gray code (``code="gray"``), which OpenCV's decoder can check."""
    return render(gray_code_patterns(PROJ, code="gray"))


def opencv_decode(images, proj, threshold=5):
    hp, wp = proj
    g = cv2.structured_light.GrayCodePattern.create(wp, hp)
    g.setWhiteThreshold(threshold)
    h, w = images[0].shape
    x = np.full((h, w), -1)
    y = np.full((h, w), -1)
    ok = np.zeros((h, w), bool)
    for j in range(h):
        for i in range(w):
            err, (px, py) = g.getProjPixel(images, i, j)
            if not err:
                ok[j, i], x[j, i], y[j, i] = True, px, py
    return x, y, ok


def test_patterns_are_opencvs_plus_white_and_black():
    seq = gray_code_patterns(PROJ, code="gray")
    ok, ref = cv2.structured_light.GrayCodePattern.create(PROJ[1], PROJ[0]).generate()
    assert len(seq) == len(ref) + 2 == 2 * sum(gray_code_bits(PROJ)) + 2
    for img, r in zip(seq, ref, strict=False):  # seq ends with white and black, OpenCV's does not
        assert img.dtype == np.float32 and img.shape == PROJ + (3,)
        np.testing.assert_array_equal(img[..., 0] * 255, r)
        np.testing.assert_array_equal(img[..., 0], img[..., 2])
    assert np.all(seq[-2] == 1) and np.all(seq[-1] == 0)
    assert seq.names[0] == "gray x bit 0" and seq.names[-1] == "black"


@pytest.mark.parametrize("proj", [(768, 1024), (1080, 1920), (600, 800), (2, 3)])
def test_bit_count_matches_opencv(proj):
    n = cv2.structured_light.GrayCodePattern.create(proj[1], proj[0]).getNumberOfPatternImages()
    assert 2 * sum(gray_code_bits(proj)) == n


def test_agrees_with_opencv_getprojpixel(captures):
    pats = captures[:-2]
    ours = decode_gray_code(pats, PROJ, code="gray")
    x, y, ok = opencv_decode(pats, PROJ)
    # A meaningful test: most pixels decode, but blur and the projector's edge reject some.
    assert 0.4 < ok.mean() < 0.9
    np.testing.assert_array_equal(ours.valid, ok)
    np.testing.assert_array_equal(ours.x[ok], x[ok])
    np.testing.assert_array_equal(ours.y[ok], y[ok])
    assert ours.x.dtype == np.int32 and np.all(ours.x[~ok] == -1)


@pytest.mark.parametrize("code", GRAY_CODES)
def test_decoded_pixels_are_where_the_warp_says(code, captures):
    caps = captures if code == "gray" else render(gray_code_patterns(PROJ, code=code))
    c = decode_gray_code(caps, PROJ, code=code)  # with the white and black captures last
    tx, ty = true_warp()
    ok = c.valid
    assert ok.mean() > 0.4
    err = np.maximum(np.abs(c.x - tx), np.abs(c.y - ty))[ok]
    assert np.mean(err <= 1.0) > 0.99
    # Camera pixels whose surface point is beyond the projector are reported as unlit.
    outside = (tx > PROJ[1] + 2) | (ty > PROJ[0] + 2)
    assert outside.sum() > 100
    assert np.all(c.status[outside] == PixelStatus.UNLIT)
    assert "unlit" in c.summary()


def test_dtypes_and_colour_give_the_same_answer(captures):
    pats, white, black = captures[:-2], captures[-2], captures[-1]
    ref = decode_gray_code(pats, PROJ, white=white, black=black, threshold=4.5, shadow_threshold=40, code="gray")
    variants = [
        ([p.astype(np.uint16) * 257 for p in pats], white.astype(np.uint16) * 257, black.astype(np.uint16) * 257,
         4.5 * 257, 40 * 257),
        ([p / 255.0 for p in pats], white / 255.0, black / 255.0, 4.5 / 255, 40 / 255),
        ([np.repeat(p[..., None], 3, -1) for p in pats], np.repeat(white[..., None], 3, -1),
         np.repeat(black[..., None], 3, -1), 4.5, 40),
        (np.stack(pats), white, black, 4.5, 40),
    ]
    for p, w, b, t, s in variants:
        got = decode_gray_code(p, PROJ, white=w, black=b, threshold=t, shadow_threshold=s, code="gray")
        np.testing.assert_array_equal(got.status, ref.status)
        np.testing.assert_array_equal(got.x, ref.x)
        np.testing.assert_array_equal(got.y, ref.y)


def test_float_default_threshold_scales_with_the_data(captures):
    a = decode_gray_code([p / 255.0 for p in captures], PROJ, code="gray")
    b = decode_gray_code([p * 1e-3 for p in captures[:-2]] + [captures[-2] * 1e-3, captures[-1] * 1e-3], PROJ,
                         code="gray")
    # identical up to pixels sitting exactly on the per-pixel contrast threshold, where
    # rounding of the scaled data decides
    assert np.mean(a.status != b.status) < 0.005
    assert a.valid.mean() > 0.4


def test_inputs_are_not_modified(captures):
    before = [c.copy() for c in captures]
    decode_gray_code(captures, PROJ)
    for a, b in zip(captures, before, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("code", GRAY_CODES)
@pytest.mark.parametrize("proj", [(8, 8), (5, 13), (64, 33), (3, 2)])
def test_coaxial_ideal_rig_decodes_every_pixel(proj, code):
    seq = gray_code_patterns(proj, code=code)
    caps = [(p[..., 0] * 0.8 + 0.05).astype(np.float32) for p in seq]
    c = decode_gray_code(caps, proj, code=code)
    ident = Correspondence.identity(proj)
    np.testing.assert_array_equal(c.x, ident.x)
    np.testing.assert_array_equal(c.y, ident.y)
    assert c.valid.all()


def test_low_contrast_and_out_of_range_are_told_apart():
    proj = (3, 5)  # 3 column bits: codes 5..7 exist but are beyond the projector
    seq = gray_code_patterns(proj, code="gray")
    caps = [p[..., 0].astype(np.float32) for p in seq[:-2]]
    # Camera pixel (0, 0) sees projector column 6 (Gray 101); pixel (0, 1) sees no contrast.
    gray6 = [1, 0, 1]
    for k, g in enumerate(gray6):
        caps[2 * k][0, 0], caps[2 * k + 1][0, 0] = float(g), float(1 - g)
    for c in caps:
        c[0, 1] = 0.5
    out = decode_gray_code(caps, proj, threshold=0.1, code="gray")
    assert out.status[0, 0] == PixelStatus.OUT_OF_RANGE
    assert out.status[0, 1] == PixelStatus.LOW_CONTRAST
    assert out.counts() == {"decoded": 13, "unlit": 0, "low_contrast": 1, "out_of_range": 1}


def test_wrong_count_names_the_numbers():
    imgs = [np.zeros((2, 2), np.uint8)] * 38
    with pytest.raises(InputError, match=r"expected 40 images for a 1024×768 projector \(20 pattern pairs"):
        decode_gray_code(imgs, (768, 1024))
    with pytest.raises(InputError, match="got 38"):
        decode_gray_code(imgs, (768, 1024))


def test_bad_inputs():
    seq = gray_code_patterns((4, 4))
    caps = [p[..., 0] for p in seq]
    with pytest.raises(InputError, match="all captures must match"):
        decode_gray_code(caps[:-3] + [np.zeros((5, 4), np.float32)], (4, 4))
    with pytest.raises(InputError, match="white/black were given too"):
        decode_gray_code(caps, (4, 4), white=caps[-2], black=caps[-1])
    with pytest.raises(InputError, match="must be given together"):
        decode_gray_code(caps[:-2], (4, 4), white=caps[-2])
    with pytest.raises(InputError, match="share one dtype"):
        decode_gray_code(caps[:-3] + [np.zeros((4, 4), np.uint8)], (4, 4))
    with pytest.raises(InputError, match="grey"):
        decode_gray_code([np.zeros((4, 4, 2), np.float32)] * 8, (4, 4))
    with pytest.raises(InputError, match="projector_resolution"):
        decode_gray_code(caps, (4, 0))
    with pytest.raises(InputError, match="at least 2×2"):
        gray_code_patterns((1, 8))
    with pytest.raises(InputError, match="NaN"):
        decode_gray_code([np.full((4, 4), np.nan, np.float32)] * 8, (4, 4))
    with pytest.raises(InputError, match="code must be one of 'xor', 'gray', got 'binary'"):
        decode_gray_code(caps, (4, 4), code="binary")
    with pytest.raises(InputError, match="code must be one of"):
        gray_code_patterns((4, 4), code="binary")


def concave_corner(patterns, *, grazing=0.1, coupling=0.3):
    """Co-axial float captures of a concave corner: columns < W/2 a frontal wall, the rest a grazing one.

    The grazing wall's own direct light is ``grazing`` of the frontal one's; it also receives
    ``coupling`` times the frontal wall's lit fraction as interreflected light (and sends a
    tenth of that back) — more than its own direct light whenever most of the frontal wall is lit.
    """
    out = []
    for p in patterns:
        plane = p[..., 0].astype(np.float64)
        half = plane.shape[1] // 2
        direct = plane * np.where(np.arange(plane.shape[1]) < half, 1.0, grazing)
        from_front, from_side = plane[:, :half].mean(), plane[:, half:].mean() * grazing
        glob = np.where(np.arange(plane.shape[1]) < half, 0.1 * coupling * from_side, coupling * from_front)
        out.append((0.02 + direct + glob).astype(np.float32))
    return out


def test_xor_code_decodes_a_concave_corner_the_gray_code_gets_wrong():
    proj = (8, 64)
    truth = Correspondence.identity(proj)
    wrong = {}
    for code in GRAY_CODES:
        c = decode_gray_code(concave_corner(gray_code_patterns(proj, code=code)), proj, code=code)
        wrong[code] = int((c.valid & (c.x != truth.x)).sum() + (~c.valid).sum())
    assert wrong["gray"] > 100  # the interreflected light flips the most significant column bit
    assert wrong["xor"] == 0


def test_correspondence_validates_and_is_read_only():
    with pytest.raises(InputError, match="inside the 2×2 projector"):
        Correspondence.from_maps(np.array([[5]]), np.array([[0]]), np.array([[True]]), (2, 2))
    c = Correspondence.identity((2, 2))
    with pytest.raises(ValueError):
        c.x[0, 0] = 3
    target = np.array([[True, False], [False, False]])
    assert c.summary(target) == "all 1 target pixels decoded"
    assert not c.missing(target).any()
