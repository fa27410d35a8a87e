"""Qt app tests: the user's cache folder is a temporary one (the demo keeps its sessions there)."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def private_cache(tmp_path_factory, monkeypatch):
    """QStandardPaths' cache location (and the virtual rig's default cache) under pytest's temp dir."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path_factory.getbasetemp() / "xdg-cache"))
