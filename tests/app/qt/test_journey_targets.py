"""J4, targets: add, rename (any text), reorder, delete the selected one — and undo each, in the real window."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QListWidget

from app.model.document import Document
from tests.app.qt.user import User


def test_targets_journey(make_window, qtbot):
    doc = Document(np.full((32, 32, 3), 0.3, np.float32))
    window = make_window(doc)
    user = User(qtbot, window)
    lst = user.find("targets_list", QListWidget)

    user.click("target_add")  # the panel's +
    user.trigger("add_target")  # Targets ▸ Add Target
    user.press(Qt.Key.Key_T, Qt.KeyboardModifier.ControlModifier)  # its shortcut
    assert user.rows(lst) == ["target 1", "target 2", "target 3"] and lst.currentRow() == 2

    names = ["Wall #2 (left) — ✓", "  floor: tiles/grout  ", "x"]
    for row, name in enumerate(names):
        user.rename_row(lst, row, name)
    assert user.rows(lst) == ["Wall #2 (left) — ✓", "floor: tiles/grout", "x"]  # any text; outer spaces trimmed
    user.rename_row(lst, 2, "x")  # the same name: nothing to undo
    user.rename_row(lst, 2, "floor: tiles/grout")  # a name in use is refused, with a message, nothing lost
    assert user.rows(lst)[2] == "x" and "already used" in window.statusBar().currentMessage()

    user.select_row(lst, 2)
    user.click("target_up")
    user.click("target_up")
    assert user.rows(lst) == ["x", "Wall #2 (left) — ✓", "floor: tiles/grout"] and lst.currentRow() == 0
    user.click("target_down")
    assert user.rows(lst) == ["Wall #2 (left) — ✓", "x", "floor: tiles/grout"]

    user.select_row(lst, 1)
    user.click("target_remove")
    assert user.rows(lst) == ["Wall #2 (left) — ✓", "floor: tiles/grout"]
    assert doc.target(doc.current).name == "floor: tiles/grout" and lst.currentItem().text() == "floor: tiles/grout"
    assert window.albedo_panel.title.text() == "<b>floor: tiles/grout</b>"

    # undo each step, newest first: delete, down, up, up, three renames, three adds
    history = [
        ["Wall #2 (left) — ✓", "x", "floor: tiles/grout"],
        ["x", "Wall #2 (left) — ✓", "floor: tiles/grout"],
        ["Wall #2 (left) — ✓", "x", "floor: tiles/grout"],
        ["Wall #2 (left) — ✓", "floor: tiles/grout", "x"],
        ["Wall #2 (left) — ✓", "floor: tiles/grout", "target 3"],
        ["Wall #2 (left) — ✓", "target 2", "target 3"],
        ["target 1", "target 2", "target 3"],
        ["target 1", "target 2"],
        ["target 1"],
        [],
    ]
    for expected in history:
        user.trigger("undo")
        assert user.rows(lst) == expected
    assert not window.act_undo.isEnabled() and not doc.is_dirty()
    for expected in reversed(history[:-1]):
        user.press(Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier)
        assert user.rows(lst) == expected
    user.trigger("redo")
    assert user.rows(lst) == ["Wall #2 (left) — ✓", "floor: tiles/grout"] and doc.is_dirty()
