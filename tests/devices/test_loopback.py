"""The loopback bench's parts that need no second screen: its DNG files, options and probe.

The bench itself runs in tests/two_screens/test_loopback.py (a child process with two screens).
"""

from __future__ import annotations

import numpy as np
import pytest

import devices
from devices.loopback import linear_dng
from engine.errors import DeviceError, InputError
from engine.raw import decode_raw


def test_linear_dng_decodes_to_the_sensor_values_and_flags_clipping():
    rng = np.random.default_rng(0)
    raw = rng.integers(400, 16384, size=(24, 32, 3)).astype(np.uint16)
    raw[3, 4, 1] = 16383  # clipped
    decoded = decode_raw(linear_dng(raw, black=512, white=16383))
    expected = np.maximum(raw.astype(np.float32) - 512, 0) / (16383 - 512)
    np.testing.assert_allclose(decoded.image, expected, atol=1e-7)
    assert decoded.saturated.sum() == 1 and decoded.saturated[3, 4]
    assert (decoded.black_level, decoded.white_level) == (512.0, 16383.0)


def test_a_linear_dng_cut_short_is_unreadable_not_incomplete():
    """Its directory comes last: a half-written file fails to decode (the hot folder then waits),
    it never decodes with missing pixels."""
    data = linear_dng(np.full((24, 32, 3), 1000, np.uint16), black=512, white=16383)
    for cut in range(8, len(data) - 4, 97):  # the last 4 bytes only end the directory chain
        with pytest.raises(InputError, match="cannot decode RAW data"):
            decode_raw(data[:cut])


def test_options_faults_and_the_missing_second_screen():
    with pytest.raises(InputError, match=r"unknown loopback rig option\(s\) \['iso'\]"):
        devices.open_rig("loopback:cornell", iso=100)
    with pytest.raises(InputError, match=r"faults must map shot numbers \(from 1\) to one of \['drop', 'partial', "):
        devices.open_rig("loopback:cornell", faults={0: "drop"})
    with pytest.raises(InputError, match="file_format must be one of"):
        devices.open_rig("loopback:cornell", file_format="jpeg")
    with pytest.raises(InputError, match="the loopback bench's projector is a screen window"):
        devices.open_rig("loopback:cornell", projector="vga:1")
    with pytest.raises(DeviceError, match="no second screen for the projector"):
        devices.open_rig("loopback:cornell")  # the offscreen test platform has one screen
    from devices.virtual import scene_names

    entries = [a for a in devices.available() if a.name.startswith("loopback:")]
    assert [a.name for a in entries] == [f"loopback:{name}" for name in scene_names()]  # every virtual scene
    assert not entries[0].ok and "pass projector='qtscreen:0'" in entries[0].reason
