"""The headless CLI: help everywhere, the demo end to end, one-line errors and exit codes."""

import subprocess
import sys

import numpy as np
import pytest

from app.cli.main import COMMANDS
from app.main import main
from engine.imageio import read_image, read_metadata


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "app.main", *args], capture_output=True, text=True, cwd=cwd, timeout=600)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_has_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert command in capsys.readouterr().out


def test_demo_runs_the_whole_pipeline_and_scores_it(tmp_path):
    out = tmp_path / "demo"
    result = _run("demo", "-o", str(out), "--ideal", "--resolution", "32", "--frames", "1", "--denoise", "0")
    assert result.returncode == 0, result.stderr
    error = float(result.stdout.strip())
    assert error < 0.5  # percent, ideal rig at 32x32
    assert "relative error vs ground truth" in result.stderr
    for name in ("recolored.exr", "recolored.png", "truth.png", "error.png", "photograph.png"):
        assert (out / name).exists(), name
    assert read_image(out / "recolored.exr").shape == (32, 32, 3)
    assert "albedit.edit" in read_metadata(out / "recolored.exr")
    # the headless recolor of the demo's session writes the same image
    again = _run("recolor", str(out / "session"), "--kappa", "2,0.125,8", "-o", str(tmp_path / "again.exr"))
    assert again.returncode == 0, again.stderr
    np.testing.assert_allclose(read_image(tmp_path / "again.exr"), read_image(out / "recolored.exr"), rtol=1e-6)
    exported = _run("export", str(out / "session"), "-o", str(tmp_path / "export.tif"))
    assert exported.returncode == 0, exported.stderr
    np.testing.assert_allclose(read_image(tmp_path / "export.tif"), read_image(out / "recolored.exr"), rtol=1e-6)


@pytest.mark.parametrize(
    "args, message",
    [
        (["recolor", "{tmp}/nowhere", "--kappa", "1", "-o", "{tmp}/x.exr"], "no session folder"),
        (["recolor", "{tmp}", "--kappa", "-1", "-o", "{tmp}/x.exr"], "non-negative"),
        (["capture", "{tmp}/nowhere", "--target", "right_wall"], "no session folder"),
        (["calibrate", "{tmp}/s", "--rig", "nosuch:0"], "unknown rig backend"),
        (["demo", "-o", "{tmp}/d", "--target", "ceiling", "--resolution", "16"], "has no target"),
    ],
)
def test_bad_input_gives_one_line_errors_and_nonzero_exit(tmp_path, args, message):
    result = _run(*[a.format(tmp=tmp_path) for a in args])
    assert result.returncode != 0
    lines = [line for line in result.stderr.strip().splitlines() if line.strip()]
    assert message in lines[-1]
    assert "Traceback" not in result.stderr


def test_a_calibration_is_reused_across_sessions_of_the_same_rig_only(tmp_path):
    rig = ["--rig", "virtual:cornell", "--ideal", "--resolution", "24"]
    assert _run("calibrate", str(tmp_path / "cal"), *rig).returncode == 0
    reused = _run("capture", str(tmp_path / "s2"), *rig, "--calibration", str(tmp_path / "cal"), "--target", "right_wall", "--order", "2")
    assert reused.returncode == 0, reused.stderr
    other = _run("capture", str(tmp_path / "s3"), "--rig", "virtual:cornell", "--ideal", "--resolution", "32",
                 "--calibration", str(tmp_path / "cal"), "--target", "right_wall", "--order", "2")
    assert other.returncode == 1
    assert "calibration was made for camera 24×24" in other.stderr.strip().splitlines()[-1]
    assert not (tmp_path / "s3").exists()
