"""Issue 11, items 6 and 7: a bad cache entry is missing and recomputed (saying so); swapped captures are refused."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from engine.decompose import Decomposition
from engine.errors import SessionError
from engine.imageio import read_image
from engine.session import Session
from engine.workflow import load_decomposition
from tests.faults.conftest import refused, same_decomposition


def _entry(path: Path) -> Path:
    (entry,) = (p for p in (path / "cache").glob("*.npz") if "-trusted" not in p.name)  # the decomposition's
    return entry


def _rewrite(entry: Path, change) -> None:
    arrays = dict(np.load(entry))
    change(arrays)
    with open(entry, "wb") as fh:
        np.savez(fh, **arrays)


@pytest.mark.parametrize(
    ("damage", "why"),
    [
        (lambda a: a.update(components=a["components"][:, :8]), "unreached must be a float array of shape (8, 16, 3)"),
        (lambda a: a.update(components=a["components"][:, :8], unreached=a["unreached"][:8], target=a["target"][:8],
                            residual=a["residual"][:8], **({"covariance": a["covariance"][:, :8]}
                                                           if "covariance" in a else {})),
         "it is 16×8, the session 16×16"),
        (lambda a: a["components"].__setitem__((0, 3, 3, 0), np.nan), "non-finite"),
        (lambda a: a.pop("components"), "lack ['components']"),
        (lambda a: a.update(target=a["target"].astype(np.float32)), "target must be a bool array"),
    ],
    ids=["components-shape", "all-shapes", "nan", "missing-key", "target-dtype"],
)
def test_a_bad_cache_entry_is_recomputed_and_said_so(captured, tmp_path, albedit, tally, damage, why):
    expected = tmp_path / "expected.exr"
    assert albedit("export", captured, "-o", expected)[0] == 0
    _rewrite(_entry(captured), damage)
    tally.injected += 1
    rc, lines = albedit("export", captured, "-o", tmp_path / "out.exr")
    assert rc == 0
    assert any("was unusable" in line and why in line and "recomputed it from the captures" in line for line in lines)
    np.testing.assert_array_equal(read_image(tmp_path / "out.exr"), read_image(expected))
    tally.resumed += 1
    arrays = np.load(_entry(captured))  # the recomputed result replaced the bad entry
    assert Decomposition.from_arrays(dict(arrays)).shape == (16, 16, 3)


def test_a_cache_copied_from_another_session_is_never_used(captured, captured_template, tmp_path, open_rig, tally):
    from engine.acquire import CaptureSettings
    from engine.workflow import open_session_for_rig, run_calibration, run_capture

    other = open_rig(seed=11)  # the same plan, other captures (other noise)
    session = open_session_for_rig(tmp_path / "other", other)
    run_calibration(other, session, levels=5)
    result = run_capture(other, session, [("right_wall", other.targets["right_wall"])], 2,
                         settings=CaptureSettings(per_channel=False))
    mine = load_decomposition(Session.open(captured))
    assert not same_decomposition(mine, result.decomposition)
    for entry in (captured / "cache").glob("*.npz"):
        entry.unlink()
    shutil.copy(_entry(tmp_path / "other"), captured / "cache")  # "the same plan": copied in
    tally.injected += 1
    assert same_decomposition(load_decomposition(Session.open(captured)), mine)


def _swap(path: Path, a: str, b: str) -> None:
    """Swap two capture files, and their size and checksum in the manifest (so both still agree)."""
    fa, fb = path / "captures" / f"{a}.exr", path / "captures" / f"{b}.exr"
    data_a, data_b = fa.read_bytes(), fb.read_bytes()
    for f, data in ((fa, data_b), (fb, data_a)):
        os.chmod(f, 0o644)
        f.write_bytes(data)
    manifest = json.loads((path / "manifest.json").read_text())
    entries = {c["name"]: c for c in manifest["captures"]}
    for key in ("sha256", "bytes"):
        entries[a][key], entries[b][key] = entries[b][key], entries[a][key]
    (path / "manifest.json").write_text(json.dumps(manifest))


@pytest.mark.parametrize("pair", [("cal-xor-000", "cal-xor-001"), ("acq-photograph", "acq-r1-rgb")])
def test_swapped_captures_are_refused(captured, tmp_path, albedit, tally, pair):
    _swap(captured, *pair)
    tally.injected += 1
    for verify in (False, True):
        with pytest.raises(SessionError, match=f"holds the capture recorded as {pair[1]!r}.*swapped or replaced"):
            Session.open(captured, verify=verify)
    refused(albedit, tally, "export", captured, "-o", tmp_path / "out.exr", match="swapped or replaced")
    assert not (tmp_path / "out.exr").exists()
