"""Qt app tests: the user's home and cache folders are temporary ones (the demo keeps its sessions in the
cache; the wizard proposes session folders under the home)."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def private_cache(tmp_path_factory, tmp_path, monkeypatch):
    """QStandardPaths' cache location (and the virtual rig's set-up cache: shared, built once) and the
    home folder (one per test) under pytest's temp dir."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path_factory.getbasetemp() / "xdg-cache"))
    monkeypatch.setenv("HOME", str(tmp_path / "home"))


@pytest.fixture
def realistic_demo(make_window, qtbot, monkeypatch):
    """The window after File ▸ Demo on the realistic rig made small (48²): ``(window, user)``."""
    import app.model.demo
    from tests.app.qt.user import User

    real = app.model.demo.open_demo
    monkeypatch.setattr(app.model.demo, "open_demo",
                        lambda name, **kw: real(name, **dict(kw, resolution=(48, 48), ideal=False)))
    window = make_window()
    user = User(qtbot, window)
    user.trigger("demo")
    return window, user
