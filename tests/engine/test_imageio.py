"""Tests of engine.imageio: round trips, metadata, RAW decoding, atomic writes, errors."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest
import rawpy

from engine.errors import InputError
from engine.imageio import (
    atomic_write,
    image_info,
    read_image,
    read_metadata,
    srgb_decode,
    srgb_encode,
    to_display,
    write_image,
)
from engine.raw import decode_raw, raw_postprocess_options, read_raw_bytes
from tests.standins import check_standin, stands_in_for


def _image(shape=(7, 9, 3), *, low=0.0, high=1.0, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(low, high, size=shape).astype(np.float32)


# ----------------------------------------------------------------------------- a tiny DNG


def make_dng(raw: np.ndarray, *, black: int = 64, white: int = 4095) -> bytes:
    """A minimal uncompressed little-endian RGGB CFA DNG that LibRaw decodes (≥ 22 px each way)."""
    raw = np.ascontiguousarray(raw, dtype="<u2")
    h, w = raw.shape
    data = raw.tobytes()
    codes = {1: "B", 3: "H", 4: "I"}
    entries = []

    def add(tag, typ, values):
        if typ == 2:
            payload = values.encode() + b"\0"
            count = len(payload)
        elif typ in (5, 10):
            payload = b"".join(struct.pack("<II" if typ == 5 else "<ii", *v) for v in values)
            count = len(values)
        else:
            payload = struct.pack(f"<{len(values)}{codes[typ]}", *values)
            count = len(values)
        entries.append((tag, typ, count, payload))

    add(254, 4, [0])
    add(256, 4, [w])
    add(257, 4, [h])
    add(258, 3, [16])
    add(259, 3, [1])
    add(262, 3, [32803])  # CFA
    add(271, 2, "Albedit")
    add(272, 2, "Test")
    add(273, 4, [0])  # strip offset, patched below
    add(277, 3, [1])
    add(278, 4, [h])
    add(279, 4, [len(data)])
    add(284, 3, [1])
    add(33421, 3, [2, 2])
    add(33422, 1, [0, 1, 1, 2])  # R G / G B
    add(50706, 1, [1, 4, 0, 0])
    add(50708, 2, "Albedit Test")
    add(50714, 4, [black])
    add(50717, 4, [white])
    add(50721, 10, [(1, 1), (0, 1), (0, 1), (0, 1), (1, 1), (0, 1), (0, 1), (0, 1), (1, 1)])
    add(50728, 5, [(1, 1), (1, 1), (1, 1)])
    entries.sort()
    extra_offset = 8 + 2 + 12 * len(entries) + 4
    ifd, extra, strip_at = bytearray(struct.pack("<H", len(entries))), b"", None
    for tag, typ, count, payload in entries:
        head = struct.pack("<HHI", tag, typ, count)
        if tag == 273:
            strip_at = len(ifd) + 8
            ifd += head + b"\0" * 4
        elif len(payload) <= 4:
            ifd += head + payload.ljust(4, b"\0")
        else:
            extra += b"\0" * (len(extra) % 2)
            ifd += head + struct.pack("<I", extra_offset + len(extra))
            extra += payload
    ifd += struct.pack("<I", 0)
    extra += b"\0" * (len(extra) % 2)
    ifd[strip_at : strip_at + 4] = struct.pack("<I", extra_offset + len(extra))
    return b"II*\0" + struct.pack("<I", 8) + bytes(ifd) + extra + data


def _bayer(h=32, w=48, *, r, g, b, black=64, white=4095):
    """A flat RGGB mosaic whose channels are fractions r, g, b of (white - black) above black."""
    span = white - black
    raw = np.empty((h, w), np.uint16)
    raw[0::2, 0::2] = black + round(r * span)
    raw[0::2, 1::2] = black + round(g * span)
    raw[1::2, 0::2] = black + round(g * span)
    raw[1::2, 1::2] = black + round(b * span)
    return raw


# ----------------------------------------------------------------------------- round trips


def test_float_exr_round_trip_is_exact(tmp_path):
    image = _image(low=-2.0, high=5000.0)  # HDR, negative noise allowed in float files
    write_image(tmp_path / "a.exr", image)
    back = read_image(tmp_path / "a.exr")
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, image)


def test_half_exr_round_trip_within_half_precision(tmp_path):
    image = _image(low=1e-3, high=1000.0, seed=1)
    write_image(tmp_path / "h.exr", image, dtype="half")
    back = read_image(tmp_path / "h.exr")
    assert image_info(tmp_path / "h.exr").dtype == "half"
    rel = np.abs(back - image) / image
    assert rel.max() <= 2.0**-11
    assert rel.max() > 0  # really stored as half


def test_float_tiff_round_trip_is_exact(tmp_path):
    image = _image(low=0.0, high=30.0, seed=2)
    write_image(tmp_path / "f.tif", image)
    np.testing.assert_array_equal(read_image(tmp_path / "f.tif"), image)


@pytest.mark.parametrize(
    ("name", "dtype", "srgb_stored"),
    [("l.tif", "uint16", False), ("s.tiff", "uint8", True), ("p.png", "uint8", True), ("q.png", "uint16", True)],
)
def test_integer_round_trip_within_one_code_value(tmp_path, name, dtype, srgb_stored):
    image = _image(seed=3)
    write_image(tmp_path / name, image, dtype=dtype)
    assert image_info(tmp_path / name).dtype == dtype
    back = read_image(tmp_path / name)
    assert back.dtype == np.float32 and back.shape == image.shape
    step = 1.0 / (255 if dtype == "uint8" else 65535)
    # quantisation happens in the stored (encoded) domain: at most half a code value there
    stored, original = (srgb_encode(back), srgb_encode(image)) if srgb_stored else (back, image)
    assert np.abs(stored - original).max() <= 0.5 * step + 1e-6
    # and the stored values really are encoded (or not) as documented
    raw = read_image(tmp_path / name, srgb=False)
    np.testing.assert_allclose(raw, srgb_encode(image) if srgb_stored else image, atol=0.5 * step + 1e-6)


def test_integer_arrays_are_written_verbatim(tmp_path):
    display = to_display(_image(seed=4) * 3.0)
    write_image(tmp_path / "d.png", display)
    back = read_image(tmp_path / "d.png", srgb=False)
    np.testing.assert_array_equal(np.rint(back * 255).astype(np.uint8), display)


def test_grey_and_alpha_channels(tmp_path):
    grey = _image((5, 6), seed=5)
    write_image(tmp_path / "g.exr", grey)
    back = read_image(tmp_path / "g.exr")
    assert back.shape == (5, 6, 1)
    np.testing.assert_array_equal(back[..., 0], grey)
    rgba = _image((5, 6, 4), seed=6)
    write_image(tmp_path / "a.png", rgba, dtype="uint16")
    back = read_image(tmp_path / "a.png")
    np.testing.assert_allclose(back[..., 3], rgba[..., 3], atol=1e-4)  # alpha is never sRGB-decoded
    np.testing.assert_allclose(back[..., :3], rgba[..., :3], atol=1e-4)


@pytest.mark.parametrize("name", ["m.exr", "m.tif", "m.png"])
def test_metadata_round_trip(tmp_path, name):
    edit = {"targets": ["wall"], "κ": [1.5, 0.5, 0.25], "order": 4, "nested": {"a": None, "b": True}}
    write_image(tmp_path / name, _image(), metadata={"edit": edit, "note": "déjà"})
    assert read_metadata(tmp_path / name) == {"edit": edit, "note": "déjà"}


def test_files_without_metadata_give_empty_dict(tmp_path):
    write_image(tmp_path / "n.exr", _image())
    assert read_metadata(tmp_path / "n.exr") == {}


def test_channel_names_mode_and_exclusive(tmp_path):
    path = tmp_path / "c.exr"
    write_image(path, _image((3, 4, 4)), channel_names=("R", "G", "B", "saturated"), mode=0o444, exclusive=True)
    assert image_info(path).channel_names == ("R", "G", "B", "saturated")
    assert os.stat(path).st_mode & 0o777 == 0o444
    before = path.read_bytes()
    with pytest.raises(FileExistsError):
        write_image(path, _image((3, 4, 4), seed=9), exclusive=True)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.exr"]


# ----------------------------------------------------------------------------- atomicity


def test_failed_replace_leaves_old_file_and_no_partial_file(tmp_path, monkeypatch):
    path = tmp_path / "keep.exr"
    write_image(path, _image(seed=7))
    before = path.read_bytes()

    def broken_replace(src, dst):
        raise OSError("disk pulled out")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(InputError, match=r"keep\.exr.*disk pulled out.*unchanged"):
        write_image(path, _image(seed=8))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.exr"]


def test_failed_writer_leaves_nothing(tmp_path):
    def writer(temp):
        temp.write_bytes(b"half a fi")
        raise OSError("crash while writing")

    with pytest.raises(OSError, match="crash while writing"):
        atomic_write(tmp_path / "x.bin", writer)
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- errors


def test_read_errors_name_the_path_and_problem(tmp_path):
    with pytest.raises(InputError, match=r"nope\.exr: no such file"):
        read_image(tmp_path / "nope.exr")
    (tmp_path / "x.bmp").write_bytes(b"BM")
    with pytest.raises(InputError, match=r"x\.bmp: unsupported image extension '\.bmp'"):
        read_image(tmp_path / "x.bmp")
    (tmp_path / "bad.exr").write_bytes(b"garbage" * 20)
    with pytest.raises(InputError, match=r"bad\.exr: cannot read image"):
        read_image(tmp_path / "bad.exr")
    write_image(tmp_path / "t.png", _image((40, 50, 3)))
    data = (tmp_path / "t.png").read_bytes()
    (tmp_path / "t.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"t\.png: corrupt or truncated"):
        read_image(tmp_path / "t.png")
    (tmp_path / "dir.exr").mkdir()
    with pytest.raises(InputError, match="not a regular file"):
        read_metadata(tmp_path / "dir.exr")


@pytest.mark.parametrize(
    ("name", "image", "options", "match"),
    [
        ("n.exr", np.full((2, 2, 3), np.nan, np.float32), {}, r"n\.exr: image contains 12 non-finite"),
        ("x.jpg", np.zeros((2, 2, 3), np.float32), {}, r"x\.jpg: cannot write extension '\.jpg'"),
        ("d.exr", np.zeros((2, 2, 3), np.float32), {"dtype": "uint8"}, r"dtype for \.exr files must be one of"),
        ("r.png", np.full((2, 2, 3), 1.5, np.float32), {}, r"r\.png: a uint8 file holds \[0, 1\].*to_display"),
        ("o.exr", np.full((2, 2, 3), 1e5, np.float32), {"dtype": "half"}, "overflow half floats"),
        ("s.exr", np.zeros((2, 2, 5), np.float32), {}, r"shape \(H, W\) or \(H, W, C\)"),
        ("i.exr", np.zeros((2, 2, 3), np.int32), {}, "dtype int32"),
        ("m.exr", np.zeros((2, 2, 3), np.float32), {"metadata": {"k": object()}}, "not JSON-serialisable"),
        ("k.exr", np.zeros((2, 2, 3), np.float32), {"metadata": {"a b": 1}}, "metadata key 'a b'"),
        ("v.png", np.zeros((2, 2, 3), np.uint8), {"dtype": "uint16"}, "written verbatim and needs dtype='uint8'"),
    ],
)
def test_write_errors(tmp_path, name, image, options, match):
    with pytest.raises(InputError, match=match):
        write_image(tmp_path / name, image, **options)
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- display


def test_to_display_matches_the_srgb_formula_and_clips_only_for_display():
    image = _image((64, 64, 3), low=-0.5, high=2.0, seed=10)
    out = to_display(image)
    assert out.dtype == np.uint8 and out.shape == image.shape
    exact = np.rint(srgb_encode(np.clip(image.astype(np.float64), 0, 1)) * 255)
    assert np.abs(out.astype(int) - exact).max() <= 1
    assert np.all(out[image >= 1.0] == 255) and np.all(out[image <= 0.0] == 0)
    np.testing.assert_array_equal(to_display(image / 4, exposure=2.0), out)
    assert to_display(image[..., 0]).shape == (64, 64)
    with pytest.raises(InputError, match="non-finite"):
        to_display(np.full((2, 2), np.inf, np.float32))
    with pytest.raises(InputError, match="exposure must be a finite"):
        to_display(image, exposure=float("nan"))


def test_srgb_decode_inverts_encode():
    x = np.linspace(-0.01, 1.2, 1001)
    np.testing.assert_allclose(srgb_decode(srgb_encode(x)), x, rtol=1e-12, atol=1e-15)
    assert srgb_encode(np.float32([0.5])).dtype == np.float32


# ----------------------------------------------------------------------------- RAW


def test_dng_decodes_linearly_black_removed_white_one(tmp_path):
    data = make_dng(_bayer(r=0.5, g=0.25, b=0.125), black=64, white=4095)
    (tmp_path / "flat.dng").write_bytes(data)
    image = read_image(tmp_path / "flat.dng")
    assert image.dtype == np.float32 and image.shape == (32, 48, 3)
    # camera RGB, no white balance, no gamma: the mosaic fractions come back per channel
    np.testing.assert_allclose(image.reshape(-1, 3).mean(0), [0.5, 0.25, 0.125], atol=2e-4)
    np.testing.assert_array_equal(read_raw_bytes(data), image)
    np.testing.assert_array_equal(read_raw_bytes(memoryview(data)), image)
    # black level is zero, white level is one
    assert read_raw_bytes(make_dng(_bayer(r=0, g=0, b=0))).max() == 0.0
    assert read_raw_bytes(make_dng(_bayer(r=1, g=1, b=1))).min() == 1.0


def test_dng_brightness_is_linear_across_frames():
    # A frame whose maximum is 0.9 of white stays at 0.9: LibRaw's default adjust_maximum_thr
    # (0.75) would rescale it by its own maximum, so two frames of different brightness
    # would no longer be comparable.
    dim, bright = make_dng(_bayer(r=0.3, g=0.3, b=0.3)), make_dng(_bayer(r=0.9, g=0.9, b=0.9))
    ratio = read_raw_bytes(bright).mean() / read_raw_bytes(dim).mean()
    assert ratio == pytest.approx(3.0, rel=1e-3)
    assert read_raw_bytes(bright).mean() == pytest.approx(0.9, abs=1e-3)
    options = raw_postprocess_options()
    options.pop("adjust_maximum_thr")
    import io

    with rawpy.imread(io.BytesIO(bright)) as raw:
        default = raw.postprocess(**options) / 65535.0
    assert default.mean() > 0.95  # what the guard prevents


@stands_in_for("rawpy:RawPy", attributes=("raw_type", "raw_image_visible", "white_level", "black_level_per_channel"))
class RawStandIn:
    """rawpy's RawPy: a mosaic file; records the postprocess options; a white frame."""

    _calls: list = []
    raw_type = rawpy.RawType.Flat
    raw_image_visible = np.full((2, 3), 4095, np.uint16)
    white_level = 4095
    black_level_per_channel = [64, 64, 64, 64]

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc_val, exc_tb):
        return None

    def postprocess(self, params=None, **kw):
        self._calls.append(kw)
        return np.full((2, 3, 3), 65535, np.uint16)


def test_raw_standin_matches_rawpy():
    assert check_standin(RawStandIn) == []


def test_raw_uses_exactly_the_linear_postprocess_options(monkeypatch):
    monkeypatch.setattr(RawStandIn, "_calls", [])
    monkeypatch.setattr(rawpy, "imread", lambda source: RawStandIn())
    raw = decode_raw(b"stand-in")
    assert RawStandIn._calls == [
        {
            "gamma": (1, 1),
            "no_auto_bright": True,
            "output_bps": 16,
            "output_color": rawpy.ColorSpace.raw,
            "user_wb": [1.0, 1.0, 1.0, 1.0],
            "adjust_maximum_thr": 0.0,
            "user_flip": 0,
        }
    ]
    np.testing.assert_array_equal(raw.image, np.ones((2, 3, 3), np.float32))
    assert raw.saturated.all() and (raw.black_level, raw.white_level) == (64.0, 4095.0)
    np.testing.assert_array_equal(read_raw_bytes(b"stand-in"), raw.image)


def test_raw_errors(tmp_path):
    with pytest.raises(InputError, match=r"DSC_1\.NEF: cannot decode RAW data"):
        read_raw_bytes(b"\0" * 100, name="DSC_1.NEF")
    with pytest.raises(InputError, match="RAW data is empty"):
        read_raw_bytes(b"")
    with pytest.raises(InputError, match="data must be bytes, got str"):
        read_raw_bytes("IMG.CR2")
    (tmp_path / "bad.cr2").write_bytes(b"not raw at all" * 10)
    with pytest.raises(InputError, match=r"bad\.cr2: cannot decode RAW data"):
        read_image(tmp_path / "bad.cr2")
    (tmp_path / "x.dng").write_bytes(make_dng(_bayer(r=0.1, g=0.1, b=0.1)))
    with pytest.raises(InputError, match="srgb=True makes no sense for a RAW file"):
        read_image(tmp_path / "x.dng", srgb=True)
    assert read_metadata(tmp_path / "x.dng") == {}
