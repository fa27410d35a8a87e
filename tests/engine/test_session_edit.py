"""The saved edit: one schema, names a user can type, older sessions read, the decomposition as plain arrays."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engine.decompose import Decomposition
from engine.errors import InputError, SessionError
from engine.session import Session
from engine.session.edit import (
    Edit,
    EditAcquisition,
    EditTarget,
    check_target_name,
    export_metadata,
    mask_digest,
    mask_name,
)
from engine.workflow import edit_from_plan, interrupted_edit, save_edit, saved_edit

CAMERA = (6, 8)


def _session(path) -> Session:
    return Session.create(path, rig_name="virtual:cornell", camera_resolution=CAMERA, projector_resolution=CAMERA)


def _mask(rows) -> np.ndarray:
    m = np.zeros(CAMERA, bool)
    m[rows] = True
    return m


def _edit() -> Edit:
    return Edit(
        targets=(EditTarget("floor", "floor-00000000", (0.5, 1.0, 1.0), (255, 0, 0)),
                 EditTarget("target 1", "target_1-11111111", (2.0, 0.125, 8.0))),
        acquisition=EditAcquisition(("floor", "target 1"), ((0.5, 1.0, 1.0), (1.0, 1.0, 1.0)), "decomposition-ab", 3),
        current="target 1",
    )


@pytest.mark.parametrize("name", ["target 1", "Wand — links", "  spaced  ", "ünïcødé", "a/b\\c:*?", "x" * 256])
def test_every_name_a_user_can_type_gets_a_safe_mask_name(tmp_path, name):
    session = _session(tmp_path / "s")
    mask = _mask(slice(1, 3))
    stored = mask_name(check_target_name(name), mask_digest(mask))
    session.write_mask(stored, mask)  # the session's strict file-name rule accepts it
    np.testing.assert_array_equal(Session.open(tmp_path / "s").read_mask(stored), mask)


def test_mask_names_differ_with_the_pixels_and_agree_for_the_same_pixels():
    a, b = _mask(slice(0, 2)), _mask(slice(2, 4))
    assert mask_name("target 1", mask_digest(a)) != mask_name("target 1", mask_digest(b))
    assert mask_name("a b", mask_digest(a)) == mask_name("a_b", mask_digest(a))  # same file, same pixels: harmless


@pytest.mark.parametrize("name", ["", "   ", "line\nbreak", "tab\there", "x" * 257, 3])
def test_names_no_user_could_type_are_refused(name):
    with pytest.raises(InputError, match="a target name must be"):
        check_target_name(name)


def test_the_edit_round_trips_through_the_session_and_its_json_is_the_schema(tmp_path):
    session = _session(tmp_path / "s")
    save_edit(session, _edit())
    assert saved_edit(Session.open(tmp_path / "s")) == _edit()
    stored = json.loads((tmp_path / "s" / "manifest.json").read_text())["state"]["edit"]
    assert stored["version"] == 2 and stored["targets"][1]["name"] == "target 1"
    assert _edit().kappa == (2.0, 0.125, 8.0)
    assert Edit().kappa == (1.0, 1.0, 1.0)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda e: e["targets"][0].update(kappa=[1, 2]), r"state\.edit\.targets\[0\]\.kappa must be"),
        (lambda e: e["targets"][0].update(kappa=[1, -2, 1]), r"state\.edit\.targets\[0\]\.kappa\[1\] must be"),
        (lambda e: e["targets"][1].update(name="floor"), "repeats the target name 'floor'"),
        (lambda e: e["acquisition"].update(cascade=["floor", "nobody"]), r"cascade\[1\] must be one of the targets"),
        (lambda e: e["acquisition"].update(denoise=-1), r"state\.edit\.acquisition\.denoise must be"),
        (lambda e: e.update(current="nobody"), r"state\.edit\.current must be null or one of"),
        (lambda e: e.update(colour="red"), r"state\.edit\.colour must be absent"),
    ],
)
def test_a_malformed_edit_is_refused_naming_the_field(tmp_path, change, match):
    session = _session(tmp_path / "s")
    edit = _edit().to_json()
    change(edit)
    with pytest.raises(InputError, match=match):
        session.update(edit=edit)
    assert "edit" not in Session.open(tmp_path / "s").state


def test_the_apps_version_1_edits_still_open(tmp_path):
    session = _session(tmp_path / "s")
    session.update(edits={
        "version": 1, "photograph": None, "current": "wall",
        "targets": [{"name": "floor", "mask": "edit-aaaa", "kappa": [0.5, 1, 1], "colour": [1, 2, 3]},
                    {"name": "wall", "mask": "edit-bbbb", "kappa": [2, 2, 2]}],
        "acquisition": {"key": "decomposition-1", "cascade": ["floor", "wall"], "kappas": [[0.5, 1, 1], [1, 1, 1]],
                        "constraint": "ordered", "unreached_light": True, "denoise": 2},
    })
    edit = saved_edit(Session.open(tmp_path / "s"))
    assert [t.mask for t in edit.targets] == ["edit-aaaa", "edit-bbbb"] and edit.targets[0].colour == (1, 2, 3)
    assert edit.acquisition == EditAcquisition(("floor", "wall"), ((0.5, 1, 1), (1, 1, 1)), "decomposition-1", 2)
    assert edit.kappa == (2, 2, 2) and edit.current == "wall"
    save_edit(session, edit)  # written back in this schema, the old key gone
    assert "edits" not in session.state and session.state["edit"]["version"] == 2


def _captured_plan(session: Session, names=("floor", "right_wall")) -> None:
    masks = [_mask(slice(0, 2)), _mask(slice(3, 5))]
    for name, mask in zip(names, masks, strict=True):
        session.write_mask(name, mask)  # what the command line wrote before names were derived
    session.update(status="captured", plan={
        "targets": list(names), "masks": [mask_digest(m) for m in masks], "order": 2,
        "fixed_kappa": [[0.5, 0.5, 0.5]], "settings": {"per_channel": True, "differences": True, "tau": 1.0,
                                                       "negative": "clamp"},
        "adaptive": None, "photograph_pattern": False,
    })


def test_the_command_lines_old_edit_is_completed_from_the_plan(tmp_path):
    session = _session(tmp_path / "s")
    _captured_plan(session)
    assert saved_edit(session).kappa == (1.0, 1.0, 1.0)  # a captured plan without an edit: κ = 1
    session.update(edit={"kappa": [2.0, 0.125, 8.0]})
    edit = saved_edit(Session.open(tmp_path / "s"))
    assert [(t.name, t.mask, t.kappa) for t in edit.targets] == [
        ("floor", "floor", (0.5, 0.5, 0.5)), ("right_wall", "right_wall", (2.0, 0.125, 8.0))]
    assert edit.acquisition.cascade == ("floor", "right_wall") and edit.kappa == (2.0, 0.125, 8.0)
    assert edit_from_plan(session, 3.0, denoise=2).acquisition.denoise == 2
    with pytest.raises(SessionError, match="has no acquisition"):
        edit_from_plan(_session(tmp_path / "t"))


def test_a_target_left_out_of_the_acquisition_stays_left_out(tmp_path):
    session = _session(tmp_path / "s")
    edit = Edit(targets=(EditTarget("lamp", "lamp-00000000", included=False), EditTarget("wall", "wall-11111111")))
    save_edit(session, edit)
    stored = session.state["edit"]["targets"]
    assert stored[0]["included"] is False and "included" not in stored[1]  # absent reads as included
    assert [t.included for t in saved_edit(Session.open(tmp_path / "s")).targets] == [False, True]


def test_an_unfinished_unsaved_acquisition_opens_as_its_plans_targets(tmp_path):
    session = _session(tmp_path / "s")
    assert interrupted_edit(session) is None  # no plan
    _captured_plan(session)
    assert interrupted_edit(session) is None  # finished: saved_edit derives the acquisition
    session.update(status="capturing")
    assert saved_edit(session) is None
    edit = interrupted_edit(session)
    assert [(t.name, t.kappa) for t in edit.targets] == [("floor", (0.5, 0.5, 0.5)), ("right_wall", (1.0, 1.0, 1.0))]
    assert edit.acquisition is None and edit.current == "right_wall"
    save_edit(session, Edit(targets=edit.targets[:1]))
    assert interrupted_edit(session) is None  # the user's saved edit wins


def test_export_metadata_is_the_edit_as_files_carry_it():
    meta = export_metadata(_edit(), source="virtual:cornell", pixels={"floor": 12}, order=4, constraint="ordered")
    assert meta == {
        "version": 2, "source": "virtual:cornell",
        "targets": [
            {"name": "floor", "kappa": [0.5, 1.0, 1.0], "pixels": 12, "cascade_position": 1, "acquired": True},
            {"name": "target 1", "kappa": [2.0, 0.125, 8.0], "pixels": 0, "cascade_position": 2, "acquired": True},
        ],
        "cascade": ["floor", "target 1"], "kappa": [2.0, 0.125, 8.0], "order": 4, "constraint": "ordered", "denoise": 3,
        "recolor": None,
    }
    assert export_metadata(_edit(), source="s", pixels={}, order=4, constraint="ordered",
                           recolor="noise-aware")["recolor"] == "noise-aware"


def test_the_recolor_choice_is_saved_and_older_edits_read_as_plain(tmp_path):
    from dataclasses import replace

    edit = _edit()
    aware = replace(edit, acquisition=replace(edit.acquisition, noise_aware=True))
    assert Edit.from_json(aware.to_json()) == aware and aware.to_json()["acquisition"]["noise_aware"] is True
    old = aware.to_json()
    del old["acquisition"]["noise_aware"]  # written before the choice existed: it exported the plain recolor
    assert Edit.from_json(old).acquisition.noise_aware is False
    with pytest.raises(InputError, match="noise_aware"):
        Edit.from_json({**old, "acquisition": {**old["acquisition"], "noise_aware": "yes"}})
    session = _session(tmp_path / "s")
    _captured_plan(session)
    assert saved_edit(session).acquisition.noise_aware  # a fresh capture: the noise-aware default
    session.update(edit={"kappa": [2.0, 0.125, 8.0]})  # the command line's old edit: plain, as it was
    assert not saved_edit(Session.open(tmp_path / "s")).acquisition.noise_aware


def _decomposition() -> Decomposition:
    rng = np.random.default_rng(3)
    target = np.zeros((4, 5), bool)
    target[1:3, 1:4] = True
    return Decomposition(rng.random((3, 4, 5, 3), dtype=np.float32), rng.random((4, 5, 3), dtype=np.float32), target,
                         "nonnegative", False, rng.random((4, 5), dtype=np.float32))


def test_a_decomposition_round_trips_through_plain_arrays():
    d = _decomposition()
    back = Decomposition.from_arrays(d.to_arrays())
    for name in ("components", "unreached", "target", "residual"):
        np.testing.assert_array_equal(getattr(back, name), getattr(d, name))
    assert (back.constraint, back.unreached_light) == ("nonnegative", False)
    assert back.blended is None
    edge = np.zeros((4, 5), bool)
    edge[0, 1] = True  # a soft mask's blended edge pixel: kept, so that noise reduction of a reloaded one leaves it
    from dataclasses import replace
    np.testing.assert_array_equal(Decomposition.from_arrays(replace(d, blended=edge).to_arrays()).blended, edge)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda a: a.pop("components"), r"lack \['components'\]"),
        (lambda a: a.update(components=a["components"][:, :2]),
         r"unreached must be a float array of shape \(2, 5, 3\)"),
        (lambda a: a.update(target=a["target"].astype(np.uint8)), "target must be a bool array"),
        (lambda a: a.update(components=np.full_like(a["components"], np.nan)), "non-finite"),
        (lambda a: a.update(constraint=np.frombuffer(b"sideways".ljust(16), np.uint8)), "constraint must be one of"),
        (lambda a: a.update(flags=np.array([1, 0])), "flags or constraint are malformed"),
    ],
)
def test_malformed_decomposition_arrays_are_refused(change, match):
    arrays = dict(_decomposition().to_arrays())
    change(arrays)
    with pytest.raises(InputError, match=match):
        Decomposition.from_arrays(arrays)
