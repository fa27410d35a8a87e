"""The GenICam backend is a documented placeholder: it says why it cannot open."""

import pytest

import devices
from devices.harvesters_camera import probe
from engine.errors import DeviceError


def test_probe_and_open_say_why():
    (entry,) = probe()
    assert not entry.ok and "not implemented" in entry.reason and "hotfolder" in entry.reason
    with pytest.raises(DeviceError, match="not implemented yet; use hotfolder"):
        devices.open_rig("harvesters:0")
    assert any(a.name == "harvesters:" and not a.ok for a in devices.available())
