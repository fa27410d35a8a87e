"""``albedit checker`` and ``albedit recolor --colour/--albedo/--match`` on the virtual checker scene."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import devices
from app.main import main
from engine.colour import luminance_weights, parse_colour
from engine.imageio import read_metadata
from engine.session import Session
from engine.workflow import load_decomposition, saved_edit, target_colour

RIG = ["--rig", "virtual:checker", "--ideal", "--resolution", "96"]


def _run(*args):
    return subprocess.run([sys.executable, "-m", "app.main", *map(str, args)], capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A cascade of the right wall (κ fixed at 1) then the panel, order 2, and the scene's true albedos."""
    tmp = tmp_path_factory.mktemp("colour_cli")
    assert main(["calibrate", str(tmp / "s"), *RIG]) == 0
    assert main(["capture", str(tmp / "s"), *RIG, "--target", "right_wall", "--fixed-kappa", "1",
                 "--target", "panel", "--order", "2"]) == 0
    with devices.open_rig("virtual:checker", ideal=True, resolution=(96, 96)) as rig:
        albedo = rig.truth.albedo()
        truth = {name: albedo[rig.targets[name]].mean(axis=0).astype(np.float64) for name in ("panel", "right_wall")}
    return tmp, truth


def _kappa(session_path):
    return np.array(saved_edit(Session.open(session_path)).target("panel").kappa)


def test_an_albedo_without_a_checker_is_refused_with_the_reason_and_nothing_written(scene):
    tmp, _ = scene
    result = _run("recolor", tmp / "s", "--target", "panel", "--albedo", "0.2,0.1,0.8", "-o", tmp / "a.exr")
    assert result.returncode == 1 and "Traceback" not in result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert "cannot ask for an absolute albedo: albedo is relative" in last and "albedit checker" in last
    assert not (tmp / "a.exr").exists()


def test_a_colour_sets_kappa_and_keeping_luminance_keeps_it(scene, capsys):
    tmp, _ = scene
    assert main(["recolor", str(tmp / "s"), "--colour", "#3355cc", "-o", str(tmp / "c.exr")]) == 0
    session = Session.open(tmp / "s")
    edit = saved_edit(session)
    colour = target_colour(session, load_decomposition(session), session.read_mask(edit.target("panel").mask))
    kappa = _kappa(tmp / "s")
    np.testing.assert_allclose(colour.colour(kappa), parse_colour("#3355cc"), rtol=1e-6)
    assert read_metadata(tmp / "c.exr")["edit"]["kappa"] == pytest.approx(kappa.tolist())
    err = capsys.readouterr().err
    assert "panel: κ = (" in err and "→ #3355cc" in err
    assert main(["recolor", str(tmp / "s"), "--colour", "srgb:0.2,0.33,0.8", "--keep-luminance",
                 "-o", str(tmp / "k.exr")]) == 0
    kept = colour.colour(_kappa(tmp / "s"))
    assert kept @ luminance_weights() == pytest.approx(colour.current @ luminance_weights())
    wanted = parse_colour("srgb:0.2,0.33,0.8")
    np.testing.assert_allclose(kept / kept.sum(), wanted / wanted.sum(), rtol=1e-6)


@pytest.fixture(scope="module")
def measured(scene):
    """The scene after `albedit checker`: its stderr."""
    tmp, _ = scene
    result = _run("checker", tmp / "s", *RIG)
    assert result.returncode == 0, result.stderr
    return result.stderr


def test_a_checker_makes_albedo_absolute(scene, measured):
    tmp, truth = scene
    err = measured
    assert "colour checker (detected): 24 of 24 patches fit" in err and "corners (dark skin" in err
    panel_line = [line for line in err.splitlines() if line.startswith("panel: absolute albedo")]
    assert len(panel_line) == 1
    # typed albedo → κ → the scene's albedo (the panel is in the chart's plane: within 2 %)
    assert main(["recolor", str(tmp / "s"), "--albedo", "0.2,0.1,0.5", "-o", str(tmp / "b.exr")]) == 0
    np.testing.assert_allclose(truth["panel"] * _kappa(tmp / "s"), [0.2, 0.1, 0.5], rtol=0.02)
    # an albedo of 1 or more is refused with the reason, and nothing is written
    refused = _run("recolor", tmp / "s", "--albedo", "0.5,1.0,0.2", "-o", tmp / "x.exr")
    assert refused.returncode == 1 and not (tmp / "x.exr").exists()
    assert "impossible: a surface cannot reflect more light than it receives" in refused.stderr.splitlines()[-1]
    # so is a κ that would make it so
    too_much = _run("recolor", tmp / "s", "--kappa", "1,1,10", "-o", tmp / "x.exr")
    assert too_much.returncode == 1 and "would give the target an albedo of 1 or more (B =" in too_much.stderr
    # matching the wall gives the panel the wall's colour: the wall is out of the chart's plane, so
    # only its chromaticity is absolute (its brightness depends on how the projector reaches it)
    assert main(["recolor", str(tmp / "s"), "--match", "right_wall", "-o", str(tmp / "m.exr")]) == 0
    new = truth["panel"] * _kappa(tmp / "s")
    np.testing.assert_allclose(new / new.sum(), truth["right_wall"] / truth["right_wall"].sum(), rtol=0.02)


@pytest.mark.parametrize("args, message", [
    (["--colour", "#12345"], "cannot read the colour '#12345'"),
    (["--colour", "srgb:1.2,0,0"], "sRGB values are 0–1"),
    (["--kappa", "2", "--keep-luminance"], "--keep-luminance changes the hue of a --colour or --match request only"),
    (["--match", "nosuch"], "--match 'nosuch': the session has no such target; its other targets are ['right_wall']"),
    (["--match", "panel"], "--match names the target being recolored"),
    (["--albedo", "red"], "an albedo is one or three numbers"),
    (["--colour", "#fff", "--kappa", "1"], "not allowed with argument"),
])
def test_bad_colour_requests_are_one_line_errors(scene, args, message):
    tmp, _ = scene
    result = _run("recolor", tmp / "s", *args, "-o", tmp / "e.exr")
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert message in result.stderr.strip().splitlines()[-1]
    assert not (tmp / "e.exr").exists()


@pytest.fixture(scope="module")
def cornell(tmp_path_factory):
    """virtual:cornell (ideal, 32²), its right wall captured at order 2."""
    path = tmp_path_factory.mktemp("cornell") / "s"
    rig = ["--rig", "virtual:cornell", "--ideal", "--resolution", "32"]
    assert main(["calibrate", str(path), *rig]) == 0
    assert main(["capture", str(path), *rig, "--target", "right_wall", "--order", "2"]) == 0
    return path, rig


def test_a_recolor_the_captured_order_cannot_follow_is_written_with_a_warning(cornell, tmp_path):
    """The paper's κ on the Cornell wall at order 2: 10 % of the blue light is in the last component."""
    path, _ = cornell
    result = _run("recolor", path, "--kappa", "2,0.125,8", "-o", tmp_path / "w.exr")
    assert result.returncode == 0, result.stderr
    warning = [line for line in result.stderr.splitlines() if "warning:" in line]
    assert warning and "has not converged at order 2" in warning[0] and "in B" in warning[0]
    assert "capture a higher order or ask for a smaller change" in warning[0]
    assert (tmp_path / "w.exr").exists()


@pytest.mark.parametrize("args, message", [
    ([], "no ColorChecker found in the photograph: place its four corners by hand"),
    (["--corners", "1,1 30,1 30,20"], "corners are four x,y camera pixels"),
    (["--corners", "1,1 30,1 1,20 30,20"], "do not form a convex quadrilateral"),
    (["--corners", "1,1 40,1 40,20 1,20"], "lie outside the 32×32 image"),
])
def test_a_checker_that_cannot_be_placed_is_a_one_line_error(cornell, args, message):
    path, rig = cornell
    before = len(Session.open(path).captures)
    result = _run("checker", path, *rig, *args)
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert message in result.stderr.strip().splitlines()[-1]
    session = Session.open(path)
    assert "colour" not in session.state
    if args:  # bad corners are refused before anything is captured
        assert len(session.captures) == before


def test_the_app_model_sees_the_sessions_colours(scene, measured):
    """Opened in the app's model: the panel's albedo, the eyedropper on the wall, a typed albedo."""
    from app.model.colour import ColourEditor, session_colours
    from app.model.files import open_document

    tmp, truth = scene
    doc, session, warnings = open_document(tmp / "s")
    assert warnings == []
    editor = ColourEditor(doc, session_colours(doc, session))
    panel, wall = doc.by_name("panel"), doc.by_name("right_wall")
    assert editor.albedo_text(panel.uid).startswith("Absolute albedo ")
    np.testing.assert_allclose(editor.colour(panel.uid).albedo, truth["panel"], rtol=0.02)
    assert editor.colours[wall.uid].direct is not None and editor.colours[wall.uid].albedo is not None
    editor.request_albedo(panel.uid, [0.3, 0.3, 0.3])
    np.testing.assert_allclose(truth["panel"] * panel.kappa, 0.3, rtol=0.02)
    ys, xs = np.nonzero(wall.mask)
    editor.pick(panel.uid, xs[len(xs) // 2], ys[len(ys) // 2])
    new = truth["panel"] * panel.kappa
    np.testing.assert_allclose(new / new.sum(), truth["right_wall"] / truth["right_wall"].sum(), rtol=0.02)
    low, high = editor.kappa_range(panel.uid)
    assert low == 0 and np.all(high * editor.colour(panel.uid).albedo <= 1 + 1e-9)
