"""Device-test fixtures: the rig named with ``--device`` (registered in tests/conftest.py)."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import pytest  # noqa: E402


def _device_option(config) -> str | None:
    return config.getoption("--device", default=None)


@pytest.fixture
def device_name(request) -> str:
    """The rig name given with ``--device`` (tests using it are skipped without it)."""
    name = _device_option(request.config)
    if not name:
        pytest.skip("hardware test: give --device NAME to run it")
    return name


def write_dng(mosaic, *, black: int = 64, white: int = 4000, cfa=(0, 1, 1, 2), orientation: int = 1) -> bytes:
    """A minimal uncompressed CFA DNG (little-endian TIFF) of ``mosaic`` (H, W) uint16 that LibRaw reads.

    Colour matrix and neutral are identity, so the linear decode of a flat mosaic value v is
    (v - black) / (white - black) in every channel.
    """
    import struct

    import numpy as np

    h, w = mosaic.shape
    data = np.asarray(mosaic).astype("<u2").tobytes()
    entries = []

    def add(tag, typ, values):
        fmt = {1: "B", 3: "H", 4: "I", 5: "II", 10: "ii", 2: "s"}[typ]
        if typ == 2:
            b = values.encode() + b"\0"
            count = len(b)
        elif typ in (5, 10):
            b = b"".join(struct.pack("<" + fmt, *v) for v in values)
            count = len(values)
        else:
            b = struct.pack(f"<{len(values)}{fmt}", *values)
            count = len(values)
        entries.append((tag, typ, count, b))

    add(254, 4, [0]); add(256, 4, [w]); add(257, 4, [h]); add(258, 3, [16]); add(259, 3, [1])  # noqa: E702
    add(262, 3, [32803]); add(271, 2, "Albedit"); add(272, 2, "Test"); add(273, 4, [0])  # noqa: E702
    add(274, 3, [orientation]); add(277, 3, [1]); add(278, 4, [h]); add(279, 4, [len(data)]); add(284, 3, [1])  # noqa: E702
    add(33421, 3, [2, 2]); add(33422, 1, list(cfa)); add(50706, 1, [1, 4, 0, 0]); add(50707, 1, [1, 1, 0, 0])  # noqa: E702
    add(50708, 2, "Albedit Test"); add(50714, 4, [black]); add(50717, 4, [white])  # noqa: E702
    add(50721, 10, [(1, 1), (0, 1), (0, 1), (0, 1), (1, 1), (0, 1), (0, 1), (0, 1), (1, 1)])
    add(50728, 5, [(1, 1), (1, 1), (1, 1)]); add(50778, 3, [21])  # noqa: E702
    entries.sort()
    ifd_off, n = 8, len(entries)
    extra_off = ifd_off + 2 + 12 * n + 4
    extra, out = b"", []
    for tag, typ, count, b in entries:
        if len(b) <= 4:
            out.append([tag, typ, count, b.ljust(4, b"\0")])
        else:
            out.append([tag, typ, count, struct.pack("<I", extra_off + len(extra))])
            extra += b + (b"\0" if len(b) % 2 else b"")
    for e in out:
        if e[0] == 273:
            e[3] = struct.pack("<I", extra_off + len(extra))
    buf = b"II*\0" + struct.pack("<I", ifd_off) + struct.pack("<H", n)
    for tag, typ, count, v in out:
        buf += struct.pack("<HHI", tag, typ, count) + v
    return buf + struct.pack("<I", 0) + extra + data


@pytest.fixture
def make_dng():
    """``make_dng(mosaic, black=64, white=4000) -> bytes`` (see :func:`write_dng`)."""
    return write_dng



@pytest.fixture
def without_modules(monkeypatch):
    """``without_modules("gphoto2", ...)``: those libraries cannot be imported for this test."""
    import sys

    from tests.standins import ModuleBlocker

    def block(*names):
        for loaded in [m for m in sys.modules if m.partition(".")[0] in names]:
            monkeypatch.delitem(sys.modules, loaded)
        monkeypatch.setattr(sys, "meta_path", [ModuleBlocker(names), *sys.meta_path])

    return block
