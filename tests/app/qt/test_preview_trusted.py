"""The live preview with the noise-aware recolor: a change is drawn at once on the fast plain path, and the exact
noise-aware frame (what export writes) replaces it when the picture rests — real worker threads, no sleeps."""

from __future__ import annotations

import numpy as np

from app.model.display import recolor_rgb32
from app.model.document import Document
from app.qt.preview import PreviewController
from engine.decompose import decompose
from engine.figurate import transport_matrix
from engine.noise import pack_covariance
from engine.trust import decompose_orders, prepare_trust, recolor_trusted

KAPPA = (2.0, 0.125, 8.0)


def _acquired(order: int = 3, size: int = 32):
    """A document whose target's components halve per interaction, observed with known white noise (seeded)."""
    rng = np.random.default_rng(3)
    target = np.zeros((size, size), bool)
    target[8:24, 8:24] = True
    base = 0.3 + 0.4 * rng.random((size, size, 3))
    comps = np.stack([base * 0.5**i for i in range(order)]).astype(np.float32)
    clean = np.einsum("ij,jhwc->ihwc", transport_matrix(order), comps)
    variance = (1e-4 * clean + 1e-6).astype(np.float32)
    obs = (clean + rng.normal(size=clean.shape) * np.sqrt(variance)).astype(np.float32)
    full = np.zeros((order, order) + obs.shape[1:], np.float32)
    for i in range(order):
        full[i, i] = variance[i]
    cov = pack_covariance(full)
    doc = Document(obs[0])
    wall = doc.add_target("wall", target)
    doc.set_acquisition([wall.uid], decompose(obs, target, covariance=cov), key="decomposition-test")
    doc.set_trusted("decomposition-test", prepare_trust(decompose_orders(obs, target, cov), obs[0]))
    return doc, wall


def test_the_fast_frame_comes_first_and_the_exact_one_when_the_picture_rests(qtbot):
    doc, wall = _acquired()
    preview = PreviewController(doc, max_shape=(64, 64))
    rendered = []
    preview.worker.done.connect(lambda _rid, frame: rendered.append(frame))
    try:
        doc.set_kappa(wall.uid, KAPPA)

        def exact_on_screen() -> bool:
            f = preview.frame
            return f is not None and not f.request.fast and np.allclose(f.request.kappa, KAPPA)

        qtbot.waitUntil(exact_on_screen, timeout=60_000)
        np.testing.assert_array_equal(preview.frame.linear, recolor_trusted(doc.trusted, KAPPA).image)
        fast = [f for f in rendered if f.request.fast and np.allclose(f.request.kappa, KAPPA)]
        assert fast, "the change was first drawn on the fast path"
        np.testing.assert_array_equal(fast[-1].pixels, recolor_rgb32(doc.decomposition, KAPPA, exposure=0.0))
    finally:
        preview.close()


def test_kappa_one_shows_the_photograph_exactly(qtbot):
    doc, wall = _acquired()
    preview = PreviewController(doc, max_shape=(64, 64), synchronous=True)
    try:
        doc.set_kappa(wall.uid, 1.0)
        assert not preview.frame.request.fast
        np.testing.assert_array_equal(preview.frame.linear, doc.photograph)
    finally:
        preview.close()
