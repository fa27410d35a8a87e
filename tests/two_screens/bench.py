"""Shared by the loopback-bench tests: the scene, rig options the command line cannot give, and
running ``albedit`` in-process."""

from __future__ import annotations

import devices
from app.main import main

SCENE, TARGET, ORDER = "cornell", "right_wall", 3
CAMERA, PROJECTOR = (48, 64), (768, 1024)


def add_rig_options(monkeypatch, cache) -> dict:
    """Options the command line cannot give, added to ``devices.open_rig`` per backend: the shared
    set-up cache, and the virtual rig's projector at the bench projector's resolution and its
    pixels point-sampled like the bench camera's."""
    extra = {"loopback": {"cache_dir": cache},
             "virtual": {"cache_dir": cache, "projector_resolution": PROJECTOR, "supersample": 1}}
    real = devices.open_rig
    def open_rig(name, **options):
        return real(name, **{**options, **extra.get(name.partition(":")[0], {})})

    monkeypatch.setattr(devices, "open_rig", open_rig)
    return extra


def run_cli(capsys, *argv) -> tuple[int, list[str]]:
    """``albedit ARGV`` in this process: its exit status and stderr lines (progress bars' last state)."""
    status = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return status, [line.split("\r")[-1] for line in err.strip().splitlines()]
