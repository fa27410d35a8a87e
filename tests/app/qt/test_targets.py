"""Regression tests of the target list and the albedo controls, driven like a person (issue 10)."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QDoubleSpinBox, QListWidget, QSlider

from app.model.document import Document
from app.qt.panels import kappa_to_ticks
from tests.app.qt.user import User


@pytest.fixture
def user(make_window, qtbot):
    doc = Document(np.full((30, 40, 3), 0.25, np.float32))
    doc.add_target("floor")
    doc.mark_saved()
    return User(qtbot, make_window(doc))


def test_a_target_added_after_opening_appears_and_can_be_selected_renamed_moved(user):
    """Defect 2: the list was rebuilt with its model's signals blocked; new rows never showed."""
    lst = user.find("targets_list", QListWidget)
    user.click("target_add")
    assert user.rows(lst) == ["floor", "target 2"] and lst.currentRow() == 1
    assert lst.visualItemRect(lst.item(1)).height() > 0  # the view knows the row: it is drawn
    user.rename_row(lst, 1, "left wall: the green one")
    doc = user.window.doc
    assert [t.name for t in doc.targets] == ["floor", "left wall: the green one"]
    user.select_row(lst, 0)
    assert doc.target(doc.current).name == "floor"
    user.select_row(lst, 1)
    user.click("target_up")
    assert user.rows(lst) == ["left wall: the green one", "floor"] and lst.currentRow() == 0


def test_deleting_the_selected_target_raises_nothing_and_leaves_nothing_stale(user):
    """Defect 3: deleting the selected target raised inside a slot and left the panels on it."""
    lst = user.find("targets_list", QListWidget)
    user.click("target_add")
    user.click("target_add")
    user.select_row(lst, 1)
    doc = user.window.doc
    deleted = doc.current
    user.click("target_remove")
    assert user.rows(lst) == ["floor", "target 3"] and deleted not in [t.uid for t in doc.targets]
    assert doc.target(doc.current).name == "target 3" and lst.currentItem().text() == "target 3"
    assert "target 3" in user.find("albedo_title").text()
    user.trigger("undo")
    assert user.rows(lst) == ["floor", "target 2", "target 3"] and doc.current == deleted
    user.select_row(lst, 2)
    user.click("target_remove")
    user.click("target_remove")
    user.click("target_remove")  # the last one: nothing selected, the panels say so
    assert user.rows(lst) == [] and doc.current == -1
    assert user.find("albedo_title").text() == "No target selected"
    assert not user.find("target_remove").isEnabled()


def test_linked_kappa_keeps_its_ratio_at_the_limit(make_window, qtbot):
    """Defect 8: (2, 0.125, 8) dragged down and back on κB became (2.77, 2.77, 8)."""
    doc = Document(np.full((30, 40, 3), 0.25, np.float32))
    t = doc.add_target("wall", kappa=(2.0, 0.125, 8.0))
    user = User(qtbot, make_window(doc))
    blue = user.find("kappa_B", QSlider)
    assert user.find("kappa_link").isChecked()
    user.drag_slider(blue, [kappa_to_ticks(4.0), kappa_to_ticks(1.0), kappa_to_ticks(0.5)])
    np.testing.assert_allclose(t.kappa, [1.0, 0.0625, 4.0])  # G reached 1/16: the drag stopped there
    assert blue.value() == kappa_to_ticks(4.0)  # and the slider shows where it stopped
    user.drag_slider(blue, [kappa_to_ticks(6.0), kappa_to_ticks(8.0)])
    np.testing.assert_allclose(t.kappa / t.kappa[2], [0.25, 1 / 64, 1], rtol=1e-12)  # the ratio, exactly
    ticks_per_pixel = (blue.maximum() - blue.minimum()) / max(blue.width() - 20, 1)  # where the mouse can land
    assert abs(blue.value() - kappa_to_ticks(8.0)) <= ticks_per_pixel + 1
    user.trigger("undo")
    np.testing.assert_allclose(t.kappa, [1.0, 0.0625, 4.0])


def test_without_a_target_the_kappa_boxes_and_sliders_agree(make_window, qtbot):
    """Defect 14: with no target selected the boxes showed 0.063 while the sliders sat at 1."""
    user = User(qtbot, make_window(Document(np.full((30, 40, 3), 0.25, np.float32))))
    for c in "RGB":
        assert user.find(f"kappa_{c}", QSlider).value() == 0
        assert user.find(f"kappa_{c}_value", QDoubleSpinBox).value() == 1.0
        assert not user.find(f"kappa_{c}", QSlider).isEnabled()


def test_shortcuts_reach_the_app_after_typing_a_kappa(user):
    """Defect 10: after typing in a κ box, Ctrl+Z went to the text field, not the app."""
    doc = user.window.doc
    t = doc.target(doc.current)
    user.find("kappa_link").setChecked(False)
    user.type_into("kappa_R_value", "2")
    assert t.kappa[0] == 2.0
    user.press(Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier)  # the focus is still in the box
    assert t.kappa[0] == 1.0
    user.press(Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier)
    assert t.kappa[0] == 2.0
    user.press(Qt.Key.Key_T, Qt.KeyboardModifier.ControlModifier)  # Targets ▸ Add Target
    assert len(doc.targets) == 2
