"""The session's noise-aware data (engine.workflow.load_trusted): prepared from the captures once, cached under the
decomposition's key, read back unchanged, prepared again when the entry is unusable; no noise model → NoNoiseModel."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import devices
from engine.errors import SessionError
from engine.session import Session
from engine.trust import TrustedDecomposition, recolor_trusted
from engine.workflow import (
    NoNoiseModel,
    decomposition_key,
    load_trusted,
    run_calibration,
    run_capture,
    trusted_key,
)

KAPPA = (2.0, 0.125, 8.0)


@pytest.fixture(scope="module")
def captured(tmp_path_factory):
    """A realistic-rig session (camera noise measured by the calibration) with the right wall at order 3, 32²."""
    root = tmp_path_factory.mktemp("trusted")
    with devices.open_rig("virtual:cornell", ideal=False, resolution=(32, 32), seed=0,
                          cache_dir=tmp_path_factory.getbasetemp() / "trusted-rig-cache") as rig:
        session = Session.create(root / "s", rig_name=rig.identity, camera_resolution=rig.camera.resolution,
                                 projector_resolution=rig.projector.resolution)
        run_calibration(rig, session)
        result = run_capture(rig, session, [("right_wall", rig.targets["right_wall"])], 3)
    return session, result


def test_prepared_once_then_read_back_from_the_cache(captured):
    session, result = captured
    acq = result.acquisition
    direct = result.targets[-1][1].trust(acq.observations, acq.covariance)
    notes: list[str] = []
    first = load_trusted(session, notes=notes)
    assert trusted_key(decomposition_key(session)) in session.cache_keys() and not notes
    again = load_trusted(session, result.key)
    for t in (first, again):
        assert isinstance(t, TrustedDecomposition) and t.order == 3
        np.testing.assert_array_equal(recolor_trusted(t, KAPPA).image, recolor_trusted(direct, KAPPA).image)
        np.testing.assert_array_equal(recolor_trusted(t, 1.0).image, acq.observations[0])  # κ = 1: the photograph


def test_preparing_counts_the_captures_it_reads(captured):
    """The replay is most of the preparation: it sat at 0 % for 10-40 s in the app; it counts its captures now."""
    session, result = captured
    session.cache_discard(trusted_key(result.key))
    seen = []
    load_trusted(session, progress=lambda step, total, message: seen.append((step, total, message)))
    reads = [(s, t) for s, t, m in seen if m == "reading the acquisition's captures"]
    n = sum(c.name.startswith("acq-") for c in session.captures)  # the acquisition's captures, D's included
    assert reads[0] == (0, 2) and len(reads) > 10 and reads[-1] == (n, n + 1)  # every capture of the plan, in order
    assert [s for s, _ in reads[1:]] == sorted(s for s, _ in reads[1:])
    assert seen[-2:] == [(n, n + 1, "smoothing the interaction shares (once per acquisition)"),
                         (n + 1, n + 1, "noise-aware recolor ready")]


def test_an_unusable_cache_entry_is_prepared_again_and_said(captured):
    session, result = captured
    load_trusted(session)
    name = trusted_key(result.key)
    arrays = session.cache_get(name)
    session.cache_put(name, {k: v for k, v in arrays.items() if not k.startswith("shares")})
    notes: list[str] = []
    t = load_trusted(session, notes=notes)
    assert t.order == 3 and len(notes) == 1 and "unusable" in notes[0]


def test_an_acquisition_without_a_noise_model_says_so(captured, monkeypatch):
    import engine.workflow.trusted as trusted_module

    session, result = captured
    real = trusted_module.reacquired

    def without_noise(*args, **kwargs):  # what a session captured before the camera's noise was measured gives
        done = real(*args, **kwargs)
        return replace(done, acquisition=replace(done.acquisition, covariance=None))

    monkeypatch.setattr(trusted_module, "reacquired", without_noise)
    with pytest.raises(NoNoiseModel, match="carries no noise model") as caught:
        load_trusted(session, "decomposition-0000000000000000")
    assert isinstance(caught.value, SessionError) and "\n" not in str(caught.value)


def test_a_session_without_an_acquisition_is_refused_in_one_line(tmp_path):
    session = Session.create(tmp_path / "empty", rig_name="virtual:cornell", camera_resolution=(8, 8),
                             projector_resolution=(8, 8))
    with pytest.raises(SessionError, match="no acquisition"):
        load_trusted(session, "decomposition-0000000000000000")
