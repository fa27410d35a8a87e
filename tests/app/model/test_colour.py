"""app.model.colour: the Albedo panel's colour controls without Qt."""

from __future__ import annotations

import numpy as np
import pytest

from app.model.colour import ColourEditor, linked_kappa, session_colours
from engine.colour import kappa_limit, luminance_weights, parse_colour, to_hex
from engine.errors import InputError
from engine.target_colour import TargetColour


def _editor(doc, *, albedo=None, floor_direct=None):
    colours = session_colours(doc, None)
    wall = doc.by_name("wall").uid
    if albedo is not None or floor_direct is not None:
        d = doc.acquisition.raw
        direct = np.where(d.target[..., None], np.full(3, 0.5), 0.0).astype(np.float32)
        colours[wall] = TargetColour(d, direct=direct, albedo=albedo)
    if floor_direct is not None:
        floor = doc.by_name("floor")
        colours[floor.uid] = TargetColour(None, direct=np.where(floor.mask[..., None], floor_direct, 0.0)
                                          .astype(np.float32))
    return ColourEditor(doc, colours), wall


def test_without_a_session_only_the_free_target_has_a_colour(acquired_doc):
    editor, wall = _editor(acquired_doc)
    assert list(editor.colours) == [wall]
    with pytest.raises(InputError, match="'floor' has no measured colour"):
        editor.swatch(acquired_doc.by_name("floor").uid)
    assert editor.albedo_text(wall).startswith("albedo is relative")


def test_a_colour_request_sets_kappa_as_one_undo_step_and_the_swatch_follows(acquired_doc):
    doc = acquired_doc
    editor, wall = _editor(doc)
    before = editor.swatch(wall)
    editor.request_colour(wall, "#3355cc")
    assert editor.swatch(wall) == "#3355cc"
    np.testing.assert_allclose(editor.colour(wall).colour(doc.target(wall).kappa), parse_colour("#3355cc"))
    doc.history.undo()
    assert editor.swatch(wall) == before and np.all(doc.target(wall).kappa == 1)
    editor.request_colour(wall, "#3355cc", exposure=1)  # meant at +1 stop: half the light
    np.testing.assert_allclose(editor.colour(wall).colour(doc.target(wall).kappa), parse_colour("#3355cc") / 2)
    editor.keep_luminance = True
    editor.request_colour(wall, "lab:50,60,-40")
    c = editor.colour(wall)
    assert c.colour(doc.target(wall).kappa) @ luminance_weights() == pytest.approx(c.current @ luminance_weights())


def test_an_albedo_needs_a_reference_and_impossible_ones_change_nothing(acquired_doc):
    doc = acquired_doc
    editor, wall = _editor(doc)
    with pytest.raises(InputError, match="cannot ask for an absolute albedo: albedo is relative"):
        editor.request_albedo(wall, [0.2, 0.1, 0.8])
    editor, wall = _editor(doc, albedo=[0.1, 0.8, 0.1])
    editor.request_albedo(wall, [0.2, 0.1, 0.8])
    np.testing.assert_allclose(doc.target(wall).kappa, [2, 0.125, 8])
    assert editor.albedo_text(wall) == "Absolute albedo 0.200, 0.100, 0.800 (measured 0.100, 0.800, 0.100)"
    for impossible in ([0.2, 1.0, 0.8], [0.2, 0.1, 1.5]):
        with pytest.raises(InputError, match="impossible"):
            editor.request_albedo(wall, impossible)
    with pytest.raises(InputError, match="albedo of 1 or more"):
        editor.set_kappa(wall, [1, 1.3, 1])
    np.testing.assert_allclose(doc.target(wall).kappa, [2, 0.125, 8])
    low, high = editor.kappa_range(wall)
    # the ceiling: 1 / albedo, or the series' divergence if lower; never below the κ set now
    expected = np.maximum(np.minimum(kappa_limit(doc.acquisition.raw), [10, 1.25, 10]), [2, 0.125, 8])
    assert low == 0 and high == pytest.approx(expected) and high[1] == pytest.approx(1.25)


def test_linked_channels_keep_their_ratio_and_stop_below_albedo_one(acquired_doc):
    np.testing.assert_allclose(linked_kappa([1, 2, 4], 2, 2), [0.5, 1, 2])
    np.testing.assert_allclose(linked_kappa([1, 2, 4], 1, 4, high=[10, 10, 5]), [1.25, 2.5, 5])
    np.testing.assert_allclose(linked_kappa([1, 2, 4], 2, 0), [0, 0, 0])  # typed 0: black
    np.testing.assert_allclose(linked_kappa([1, 2, 4], 2, 0, low=1 / 16), [1 / 16, 1 / 8, 1 / 4])  # the slider's end
    np.testing.assert_allclose(linked_kappa([0, 2, 4], 0, 1), [1, 2, 4])  # from black R moves alone
    with pytest.raises(InputError, match="channel must be 0, 1 or 2"):
        linked_kappa([1, 1, 1], 3, 1)
    doc = acquired_doc
    editor, wall = _editor(doc, albedo=[0.1, 0.4, 0.1])
    _low, high = editor.kappa_range(wall)
    editor.set_kappa(wall, linked_kappa(doc.target(wall).kappa, 0, 8.0, high=high * (1 - 1e-9)))
    k = doc.target(wall).kappa  # G would reach albedo 3.2: all stop where G reaches 1
    assert k[0] == pytest.approx(k[1]) == pytest.approx(k[2]) and 0.999 < 0.4 * k[1] < 1
    editor.set_kappa(wall, linked_kappa(k, 2, 0.0, linked=False))  # 0 is black, allowed
    assert doc.target(wall).kappa[2] == 0


def test_the_eyedropper_matches_a_measured_target_or_takes_the_colour_seen(acquired_doc):
    doc = acquired_doc
    editor, wall = _editor(doc, floor_direct=[0.25, 0.5, 1.0])
    floor = doc.by_name("floor")
    ys, xs = np.nonzero(floor.mask)
    editor.pick(wall, xs[0], ys[0])
    np.testing.assert_allclose(doc.target(wall).kappa, [0.5, 1.0, 2.0], rtol=1e-6)  # the ratio of the two D
    target = doc.acquisition.raw.target
    outside = np.argwhere(~target & ~floor.mask)[0]
    editor.pick(wall, outside[1], outside[0], radius=0)
    seen = doc.photograph[outside[0], outside[1]].astype(np.float64)
    np.testing.assert_allclose(editor.colour(wall).seen * doc.target(wall).kappa, seen, rtol=1e-5)
    with pytest.raises(InputError, match="outside the 64×48 photograph"):
        editor.pick(wall, 64, 0)


def test_the_eyedropper_on_a_reference_picture_decodes_srgb(acquired_doc):
    doc = acquired_doc
    editor, wall = _editor(doc)
    reference = np.zeros((8, 8, 3), np.float32)
    reference[:] = np.array([0x33, 0x55, 0xCC]) / 255
    editor.pick_reference(wall, reference, 4, 4)
    assert editor.swatch(wall) == "#3355cc"
    assert to_hex(editor.colour(wall).colour(doc.target(wall).kappa)) == "#3355cc"
