"""Issue 11, items 8 and 10: damaged images from outside are refused, and so are files whose errors are not text."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from engine.errors import InputError
from engine.imageio import image_info, read_image, read_mask, read_metadata, write_image
from tests.faults.conftest import refused


def _write(path, pixels, **attributes):
    stored = {"float32": "float", "float16": "half"}.get(str(pixels.dtype), str(pixels.dtype))
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], stored)
    for key, value in attributes.items():
        spec.attribute(key, value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels) and out.close()


def _truncated_jpeg(path):
    _write(path, (np.random.default_rng(0).random((32, 32, 3)) * 255).astype(np.uint8))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 3])


def _nan_tiff(path):
    pixels = np.random.default_rng(1).random((32, 32, 3)).astype(np.float32)
    pixels[4:9, 2:30] = np.nan  # what a damaged float strip decodes to
    _write(path, pixels, compression="zip")


def _inf_exr(path):
    pixels = np.ones((32, 32, 3), np.float32)
    pixels[0, 0, 1] = np.inf
    _write(path, pixels)


def _truncated_piz_exr(path):
    """A PIZ EXR cut short whose header names an attribute with bytes that are not UTF-8.

    OpenEXR's own ``comp_early_eof_piz.exr`` fails the same way: the library's error message
    quotes the attribute's name, which the Python binding cannot decode.
    """
    _write(path, np.random.default_rng(2).random((32, 32, 3)).astype(np.float16), compression="piz")
    data = path.read_bytes()
    at = data.index(b"dataWindow\x00box2i\x00")
    path.write_bytes(data[:at] + b"\xfe\x00\x00" + data[at: at + 60])  # a nameless type, then the file ends


DAMAGED = [
    ("truncated.jpg", _truncated_jpeg, "corrupt or truncated image (JPEG error: Premature end of JPEG file"),
    ("strip.tif", _nan_tiff, "420 values are not finite"),
    ("sun.exr", _inf_exr, "1 values are not finite"),
    ("early_eof_piz.exr", _truncated_piz_exr, "the file's header holds bytes that are not text"),
]


@pytest.mark.parametrize(("name", "make", "match"), DAMAGED, ids=[d[0] for d in DAMAGED])
def test_damaged_images_from_outside_are_refused(tmp_path, tally, name, make, match):
    path = tmp_path / name
    make(path)
    tally.injected += 1
    for read in (read_image, read_mask):
        with pytest.raises(InputError, match=match.replace("(", r"\(")):
            read(path)
    if name.endswith(".exr") and "piz" in name:
        for read in (image_info, read_metadata):
            with pytest.raises(InputError, match="not text"):
                read(path)
    tally.refused += 1


@pytest.mark.parametrize(("name", "make", "match"), DAMAGED, ids=[d[0] for d in DAMAGED])
def test_capture_with_a_damaged_mask_file_says_so_in_one_line(tmp_path, albedit, tally, name, make, match):
    make(tmp_path / name)
    tally.injected += 1
    refused(albedit, tally, "capture", tmp_path / "s", "--resolution", "24", "--ideal",
            "--target", f"right_wall={tmp_path / name}", match=match.split(" (")[0])
    assert not (tmp_path / "s").exists()


def test_a_written_image_that_does_not_read_back_is_never_given_its_name(tmp_path, monkeypatch, tally):
    from engine import imageio

    write_image(tmp_path / "a.exr", np.ones((4, 4, 3), np.float32))
    real = imageio._fsync_file

    def truncating(path):  # a disk that drops the end of the file and says nothing
        with open(path, "r+b") as fh:
            fh.truncate(100)
        real(path)

    monkeypatch.setattr(imageio, "_fsync_file", truncating)
    tally.injected += 1
    with pytest.raises(InputError, match="does not read back"):
        write_image(tmp_path / "a.exr", np.full((4, 4, 3), 2.0, np.float32))
    monkeypatch.undo()
    np.testing.assert_array_equal(read_image(tmp_path / "a.exr"), np.ones((4, 4, 3), np.float32))  # unchanged
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr"]
