"""J6, the artist checks where an edit is unreliable: the demo on the realistic rig → drag κ →
View ▸ Predicted Noise (σ) → the canvas shows the engine's predicted standard deviation of the
(plain) recolored image, and follows κ.

Driven through the real window only (tests/app/qt/user.py); the demo's rig is the realistic one
(camera noise, half-resolution projector) made small (48²).
"""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QLabel, QSlider

from app.model.display import MAGNITUDE_MAP, false_colour, robust_max
from app.qt.panels import kappa_to_ticks
from engine.recolor import recolor_variance


def test_the_artist_sees_the_predicted_noise_of_the_edit(realistic_demo):
    window, user = realistic_demo
    doc = window.doc
    wall = doc.by_name("right_wall")
    d = doc.decomposition
    assert d is not None and d.covariance is not None  # the realistic camera's noise was measured and carried
    # the plain recolor's σ here (the noise-aware recolor's own σ: test_journey_noise_aware.py)
    user.wait_until(lambda: user.find("recolor_mode", QLabel).text() == "noise-aware recolor")
    user.trigger("noise_aware")
    assert user.find("recolor_mode", QLabel).text().startswith("plain recolor")

    # drag κ (linked) on the acquired wall, then look at the predicted noise
    user.select_row(user.find("targets_list"), 2)
    user.drag_slider(user.find("kappa_B", QSlider), [kappa_to_ticks(1.5), kappa_to_ticks(4.0)])
    assert abs(wall.kappa[2] - 4.0) < 0.1
    user.trigger("view_noise")
    assert user.action("view_noise").isChecked()

    def shows(kappa) -> bool:
        frame = window.canvas.frame
        return frame is not None and frame.view == "noise" and frame.request is not None and np.allclose(
            frame.request.kappa, kappa)

    user.wait_until(lambda: shows(wall.kappa))
    frame = window.canvas.frame
    sigma = np.sqrt(recolor_variance(d, wall.kappa))  # the engine's prediction, full resolution (48² fits)
    np.testing.assert_array_equal(frame.linear, sigma)
    rms = np.sqrt(np.mean(np.square(sigma), axis=-1))
    np.testing.assert_array_equal(frame.pixels, false_colour(rms, 0.0, robust_max(rms), MAGNITUDE_MAP))
    assert (sigma[d.target] > 0).all()
    assert user.find("view_note", QLabel).text().startswith("predicted σ on the target: mean")

    # a stronger κ amplifies the noise of the interreflections κ^(i+1): the map follows the slider
    user.drag_slider(user.find("kappa_B", QSlider), [kappa_to_ticks(4.0), kappa_to_ticks(8.0)])
    user.wait_until(lambda: shows(wall.kappa))
    stronger = np.sqrt(recolor_variance(d, wall.kappa))
    np.testing.assert_array_equal(window.canvas.frame.linear, stronger)
    assert stronger[d.target, 2].mean() > 1.5 * sigma[d.target, 2].mean()
