"""Tests of engine.session: round trips, refusals that change nothing, crash recovery."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from engine import imageio
from engine.errors import InputError, SessionError
from engine.session import SCHEMA_VERSION, Session, pattern_hash

CAMERA = (6, 8)
PROJECTOR = (4, 5)
REPO = Path(__file__).resolve().parents[2]


def _capture(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0.0, 3.0, (*CAMERA, 3)).astype(np.float32)


def _pattern(seed: int) -> np.ndarray:
    return np.random.default_rng(100 + seed).uniform(0.0, 1.0, (*PROJECTOR, 3)).astype(np.float32)


def _new(path: Path) -> Session:
    return Session.create(
        path, rig_name="virtual:cornell", camera_resolution=CAMERA, projector_resolution=PROJECTOR,
        metadata={"scene": "cornell"},
    )


@pytest.fixture
def recorded(tmp_path) -> Path:
    """A session with two captures, a mask, state and calibration."""
    session = _new(tmp_path / "s")
    for i in range(2):
        session.add_capture(f"c{i}", _capture(i), pattern_id=pattern_hash(_pattern(i)),
                            meta={"exposure": 0.01 * (i + 1)})
    session.write_mask("wall", np.eye(*CAMERA, dtype=bool))
    session.update(order=3, kappa={"wall": [1.0, 0.5, 0.5]})
    session.write_calibration({"reference": "lab-2024"},
                              {"rig": {"direct": np.ones(CAMERA, np.float32), "lut": np.arange(4.0)}})
    return tmp_path / "s"


def _snapshot(root: Path) -> dict:
    """Every entry under ``root`` (not following symlinks): kind, mode and content."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = os.lstat(p)
            if p.is_symlink():
                out[str(p.relative_to(root))] = ("link", os.readlink(p))
            elif p.is_dir():
                out[str(p.relative_to(root))] = ("dir", st.st_mode)
            else:
                out[str(p.relative_to(root))] = ("file", st.st_mode, p.read_bytes())
    return out


def _edit_manifest(root: Path, change) -> None:
    path = root / "manifest.json"
    manifest = json.loads(path.read_text())
    change(manifest)
    path.write_text(json.dumps(manifest))


# ----------------------------------------------------------------------------- round trips


def test_pattern_hash_is_stable_and_content_based():
    p = _pattern(0)
    assert pattern_hash(p) == pattern_hash(p.copy()) == pattern_hash(p.astype(np.float64))
    assert len(pattern_hash(p)) == 64
    q = p.copy()
    q[0, 0, 0] = np.nextafter(q[0, 0, 0], np.float32(2))
    assert pattern_hash(q) != pattern_hash(p)
    with pytest.raises(InputError, match="pattern must be a float array"):
        pattern_hash(np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(InputError, match="non-finite"):
        pattern_hash(np.full((2, 2, 3), np.nan))


def test_create_and_open_round_trip(recorded):
    session = Session.open(recorded, verify=True)
    assert (session.rig_name, session.camera_resolution, session.projector_resolution) == (
        "virtual:cornell", CAMERA, PROJECTOR)
    assert session.metadata == {"scene": "cornell"}
    assert [r.name for r in session.captures] == ["c0", "c1"]
    assert [r.index for r in session.captures] == [0, 1]
    assert session.captures[1].meta == {"exposure": 0.02}
    assert session.has_capture("c1") and not session.has_capture("c2")
    np.testing.assert_array_equal(session.read_capture("c1"), _capture(1))
    assert session.read_capture("c1").dtype == np.float32
    assert [r.name for r in session.find_by_pattern(pattern_hash(_pattern(0)))] == ["c0"]
    assert session.find_by_pattern(pattern_hash(_pattern(7))) == []
    assert session.state == {"order": 3, "kappa": {"wall": [1.0, 0.5, 0.5]}}
    np.testing.assert_array_equal(session.read_mask("wall"), np.eye(*CAMERA, dtype=bool))
    assert session.orphans == ()
    data, arrays = session.read_calibration()
    assert data == {"reference": "lab-2024"}
    np.testing.assert_array_equal(arrays["rig"]["direct"], np.ones(CAMERA, np.float32))
    np.testing.assert_array_equal(arrays["rig"]["lut"], np.arange(4.0))
    assert json.loads((recorded / "manifest.json").read_text())["schema_version"] == SCHEMA_VERSION


def test_captures_are_read_only_and_never_replaced(recorded):
    session = Session.open(recorded)
    file = recorded / "captures" / "c0.exr"
    assert os.stat(file).st_mode & 0o777 == 0o444
    before = _snapshot(recorded)
    with pytest.raises(SessionError, match="already has a capture named 'c0'.*never replaced"):
        session.add_capture("c0", _capture(9), pattern_id="x")
    assert _snapshot(recorded) == before


def test_saturation_mask_and_frame_metadata_round_trip(tmp_path):
    from devices.base import Frame  # a real Frame, stored through the duck-typed add_frame

    session = _new(tmp_path / "s")
    saturated = np.zeros(CAMERA, bool)
    saturated[2, 3:6] = True
    frame = Frame(_capture(3), exposure=0.5, gain=2.0, black_level=64.0, saturated=saturated, metadata={"iso": 200})
    record = session.add_frame("f", frame, pattern_id="p", meta={"note": "x"})
    assert record.meta == {"exposure": 0.5, "gain": 2.0, "black_level": 64.0, "metadata": {"iso": 200}, "note": "x"}
    loaded = Session.open(tmp_path / "s").load_capture("f")
    np.testing.assert_array_equal(loaded.image, frame.image)
    np.testing.assert_array_equal(loaded.saturated, saturated)
    assert loaded.record.has_saturated


@pytest.mark.parametrize(
    ("name", "image", "options", "match"),
    [
        ("../x", _capture(0), {}, "capture name must be"),
        ("a", _capture(0)[:3], {}, r"image must have shape \(6, 8, 3\)"),
        ("a", np.full((*CAMERA, 3), np.nan, np.float32), {}, "non-finite"),
        ("a", _capture(0), {"pattern_id": ""}, "pattern_id must be a non-empty string"),
        ("a", _capture(0), {"meta": {"x": float("nan")}}, "meta must be JSON-serialisable"),
        ("a", _capture(0), {"saturated": np.zeros(CAMERA, np.uint8)}, "saturated must be a boolean mask"),
    ],
)
def test_add_capture_input_errors_write_nothing(tmp_path, name, image, options, match):
    session = _new(tmp_path / "s")
    before = _snapshot(tmp_path / "s")
    with pytest.raises(InputError, match=match):
        session.add_capture(name, image, **{"pattern_id": "p", **options})
    assert _snapshot(tmp_path / "s") == before


def test_state_update_persists_atomically(recorded):
    session = Session.open(recorded)
    state = session.update(acquisition={"done": [0, 1]}, kappa=None, weights=np.float32([0.5, 2]))
    assert state == {"order": 3, "acquisition": {"done": [0, 1]}, "weights": [0.5, 2.0]}
    assert Session.open(recorded).state == state
    with pytest.raises(InputError, match="order must be at least 1"):
        session.update(order=0)
    with pytest.raises(InputError, match="state must be JSON-serialisable"):
        session.update(edits=object())
    assert Session.open(recorded).state == state


def test_calibration_arrays_choose_exr_or_npy_and_read_back_exactly(tmp_path):
    session = _new(tmp_path / "s")
    rng = np.random.default_rng(4)
    cases = {
        "image": rng.random((*CAMERA, 3), dtype=np.float32),  # EXR
        "grey": rng.random(CAMERA, dtype=np.float32),  # EXR, 2-D restored
        "invalid": np.where(rng.random(CAMERA) > 0.5, np.nan, 1.0).astype(np.float32),  # NaN → npy
        "double": rng.random(CAMERA),  # float64 → npy
        "index": rng.integers(0, 100, (*CAMERA, 2)).astype(np.int32),
        "valid": rng.random(CAMERA) > 0.5,
    }
    for name, array in cases.items():
        session.write_array("gray", name, array)
    files = sorted(p.name for p in (tmp_path / "s" / "calibration" / "gray").iterdir())
    assert files == ["double.npy", "grey.exr", "image.exr", "index.npy", "invalid.npy", "valid.npy"]
    reopened = Session.open(tmp_path / "s")
    for name, array in cases.items():
        back = reopened.read_array("gray", name)
        assert back.dtype == array.dtype and back.shape == array.shape
        np.testing.assert_array_equal(back, array)
    # replacing an array that changes storage removes the old file
    session.write_array("gray", "grey", np.arange(3.0))
    assert not (tmp_path / "s" / "calibration" / "gray" / "grey.exr").exists()
    # write_calibration replaces the whole calibration
    session.write_calibration({"v": 2}, {"rig": {"lut": np.zeros(2)}})
    data, arrays = Session.open(tmp_path / "s").read_calibration()
    assert data == {"v": 2} and list(arrays) == ["rig"] and list(arrays["rig"]) == ["lut"]
    assert not (tmp_path / "s" / "calibration" / "gray" / "image.exr").exists()
    with pytest.raises(SessionError, match="no calibration array 'gray/image'"):
        session.read_array("gray", "image")
    with pytest.raises(InputError, match="only numeric and bool arrays"):
        session.write_array("rig", "obj", np.array([{}], dtype=object))


def test_calibration_never_unpickles(recorded):
    session = Session.open(recorded)
    np.save(recorded / "calibration" / "rig" / "lut.npy", np.array([{"evil": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(SessionError, match=r"calibration array 'rig/lut': cannot read .*pickle"):
        session.read_array("rig", "lut")


def test_cache_round_trip_and_corrupt_entries_are_missing_and_deleted(recorded, tmp_path):
    session = Session.open(recorded)
    arrays = {"inside": np.arange(24, dtype=np.float32).reshape(2, 3, 4), "order": np.array(3)}
    session.cache_put("decomposition-wall-3", arrays)
    back = session.cache_get("decomposition-wall-3")
    assert set(back) == {"inside", "order"}
    np.testing.assert_array_equal(back["inside"], arrays["inside"])
    assert session.cache_get("absent") is None
    entry = recorded / "cache" / "decomposition-wall-3.npz"
    entry.write_bytes(entry.read_bytes()[:40])
    assert session.cache_get("decomposition-wall-3") is None and not entry.exists()
    # an npz that would need pickle is refused, then deleted
    np.savez(recorded / "cache" / "pickled.npz", x=np.array([{}], dtype=object))
    assert session.cache_get("pickled") is None and not (recorded / "cache" / "pickled.npz").exists()
    # a symlink leading outside is not followed, only removed
    outside = tmp_path / "outside.npz"
    np.savez(outside, x=np.zeros(2))
    (recorded / "cache" / "link.npz").symlink_to(outside)
    assert session.cache_get("link") is None and outside.exists() and not (recorded / "cache" / "link.npz").is_symlink()
    with pytest.raises(InputError, match="only numeric and bool arrays"):
        session.cache_put("k", {"x": np.array(["s"])})
    session.cache_put("k", {"x": np.zeros(1)})
    session.cache_put("j", {"x": np.zeros(1)})
    assert session.cache_keys() == ["j", "k"]
    session.cache_discard("j")
    session.cache_discard("j")  # already gone: nothing to do
    assert session.cache_keys() == ["k"]
    with pytest.raises(InputError, match="cache key"):
        session.cache_discard("../manifest")
    session.cache_clear()
    assert list((recorded / "cache").iterdir()) == [] and session.cache_keys() == []


def test_create_refuses_existing_content(recorded, tmp_path):
    with pytest.raises(SessionError, match="already a session; use Session.open"):
        _new(recorded)
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "photo.jpg").write_bytes(b"x")
    with pytest.raises(SessionError, match="not empty"):
        _new(tmp_path / "busy")
    with pytest.raises(TypeError, match="Session.create"):
        Session(tmp_path, {}, [])
    with pytest.raises(InputError, match="camera_resolution must be two positive integers"):
        Session.create(tmp_path / "n", rig_name="r", camera_resolution=(0, 4), projector_resolution=(2, 2))


# ----------------------------------------------------------------------------- refusals


def _corrupt_capture(root: Path):
    file = root / "captures" / "c1.exr"
    size = file.stat().st_size
    file.chmod(0o644)
    file.write_bytes(b"\0" * size)


def _truncate_capture(root: Path):
    file = root / "captures" / "c1.exr"
    file.chmod(0o644)
    file.write_bytes(file.read_bytes()[:200])


def _symlink_capture_outside(root: Path):
    outside = root.parent / "elsewhere.exr"
    outside.write_bytes((root / "captures" / "c1.exr").read_bytes())
    (root / "captures" / "c1.exr").unlink()
    (root / "captures" / "c1.exr").symlink_to(outside)


def _symlink_manifest_outside(root: Path):
    outside = root.parent / "manifest.json"
    outside.write_bytes((root / "manifest.json").read_bytes())
    (root / "manifest.json").unlink()
    (root / "manifest.json").symlink_to(outside)


def _set_capture_file(rel):
    return lambda root: _edit_manifest(root, lambda m: m["captures"][1].update(file=rel))


@pytest.mark.parametrize(
    ("damage", "match"),
    [
        (lambda r: (r / "manifest.json").unlink(), "is not a session: manifest.json is missing"),
        (lambda r: (r / "manifest.json").write_text('{"format": "albedit-session", "schema'),
         "corrupt \\(not valid JSON\\)"),
        (lambda r: (r / "manifest.json").write_bytes(b"\xff\xfe\x00"), "corrupt \\(not valid JSON\\)"),
        (lambda r: _edit_manifest(r, lambda m: m.update(schema_version=2)),
         "schema_version 2, newer than this Albedit reads"),
        (lambda r: _edit_manifest(r, lambda m: m.update(schema_version=0)), "unknown schema_version 0"),
        (lambda r: _edit_manifest(r, lambda m: m.update(schema_version="1")), "schema_version must be an integer"),
        (lambda r: _edit_manifest(r, lambda m: m.pop("format")), "not an Albedit session manifest"),
        (lambda r: _edit_manifest(r, lambda m: m["captures"][0].pop("sha256")), r"captures\[0\]\.sha256 is missing"),
        (lambda r: _edit_manifest(r, lambda m: m["captures"].append(m["captures"][0])), "repeats the name 'c0'"),
        (lambda r: (r / "captures" / "c1.exr").unlink(), r"capture 'c1' \(captures\[1\]\): file .*c1\.exr is missing"),
        (_corrupt_capture, r"capture 'c1'.*c1\.exr is corrupt"),
        (_truncate_capture, r"capture 'c1'.*c1\.exr is corrupt \(200 bytes"),
        (_set_capture_file("/etc/passwd"), "path '/etc/passwd' is absolute"),
        (_set_capture_file("C:/x.exr"), "path 'C:/x.exr' is absolute"),
        (_set_capture_file("captures/../../elsewhere.exr"), r"leads outside the session folder \('\.\.'\)"),
        (_symlink_capture_outside, r"capture 'c1'.*leads outside the session folder \(symlink"),
        (_symlink_manifest_outside, "the manifest: path 'manifest.json' leads outside"),
        (lambda r: _edit_manifest(r, lambda m: m["masks"]["wall"].update(file="../m.png")),
         "mask 'wall'.*leads outside"),
        (
            lambda r: _edit_manifest(r, lambda m: m["calibration"]["arrays"]["rig/lut"].update(file="/tmp/lut.npy")),
            "calibration array 'rig/lut'.*absolute",
        ),
    ],
)
def test_open_refuses_and_changes_nothing(recorded, damage, match):
    damage(recorded)
    before = _snapshot(recorded.parent)
    with pytest.raises(SessionError, match=match):
        Session.open(recorded)
    assert _snapshot(recorded.parent) == before


def test_a_flipped_bit_is_caught_by_checksum(recorded):
    file = recorded / "captures" / "c1.exr"
    data = bytearray(file.read_bytes())
    data[-5] ^= 0x01  # inside the compressed pixels: header and size stay valid
    file.chmod(0o644)
    file.write_bytes(bytes(data))
    before = _snapshot(recorded)
    session = Session.open(recorded)  # the quick check (size, header) passes
    with pytest.raises(SessionError, match=r"capture 'c1': .*c1\.exr is corrupt \(its checksum differs"):
        session.read_capture("c1")
    with pytest.raises(SessionError, match="checksum differs"):
        Session.open(recorded, verify=True)
    assert _snapshot(recorded) == before


def test_open_refuses_missing_folder(tmp_path):
    with pytest.raises(SessionError, match="no session folder at"):
        Session.open(tmp_path / "nothing")


# ----------------------------------------------------------------------------- crashes


def _run_crashing(script: str, root: Path) -> None:
    code = textwrap.dedent(
        f"""
        import os, sys
        from pathlib import Path
        import numpy as np
        from engine.session import Session, pattern_hash
        root = Path({str(root)!r})
        session = Session.open(root)
        """
    ) + textwrap.dedent(script)
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 17, result.stderr  # the child died where we killed it


def test_crash_between_capture_write_and_manifest_update_resumes(recorded):
    # the child dies (no cleanup, no finally) right after the capture file is complete
    _run_crashing(
        """
        from engine import session as module
        module.Session._commit = lambda self, manifest: os._exit(17)
        rng = np.random.default_rng(2)
        image = rng.uniform(0.0, 3.0, (6, 8, 3)).astype(np.float32)
        session.add_capture("c2", image, pattern_id="pattern-2", meta={"exposure": 0.03})
        """,
        recorded,
    )
    manifest_before = (recorded / "manifest.json").read_bytes()
    session = Session.open(recorded)
    assert [r.name for r in session.captures] == ["c0", "c1"]
    assert session.orphans == ("captures/c2.exr",)
    assert (recorded / "manifest.json").read_bytes() == manifest_before  # opening wrote nothing
    with pytest.raises(SessionError, match="exists but is not in the manifest.*recover_orphans"):
        session.add_capture("c2", _capture(5), pattern_id="other")
    adopted = session.recover_orphans()
    assert [(r.name, r.pattern_id, r.meta, r.index) for r in adopted] == [("c2", "pattern-2", {"exposure": 0.03}, 2)]
    assert session.orphans == ()
    reopened = Session.open(recorded, verify=True)
    assert [r.name for r in reopened.captures] == ["c0", "c1", "c2"]
    np.testing.assert_array_equal(reopened.read_capture("c2"), _capture(2))
    assert reopened.find_by_pattern("pattern-2")[0].name == "c2"


def test_crash_mid_manifest_write_keeps_old_manifest(recorded):
    # the child dies while the new manifest is half written to its temporary file
    _run_crashing(
        """
        import pathlib
        def half_then_die(self, text, encoding=None):
            with open(self, "w", encoding=encoding) as fh:
                fh.write(text[: len(text) // 2])
            os._exit(17)
        pathlib.Path.write_text = half_then_die
        session.update(order=4)
        """,
        recorded,
    )
    temps = [p.name for p in recorded.iterdir() if p.name.startswith(".manifest.json.")]
    assert len(temps) == 1 and temps[0].endswith(".tmp.json")
    session = Session.open(recorded)
    assert session.state["order"] == 3 and [r.name for r in session.captures] == ["c0", "c1"]
    assert session.orphans == ()
    session.add_capture("c2", _capture(2), pattern_id="p2")  # carries on; the stale temp is ignored
    assert [r.name for r in Session.open(recorded).captures] == ["c0", "c1", "c2"]


def test_failed_manifest_update_reports_the_orphan_in_process(recorded, monkeypatch):
    session = Session.open(recorded)
    real_replace = os.replace

    def replace(src, dst):
        if Path(dst).name == "manifest.json":
            raise OSError("disk full")
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(SessionError, match="written to .*c2.exr but the manifest could not be updated.*disk full"):
        session.add_capture("c2", _capture(2), pattern_id="p2")
    assert session.orphans == ("captures/c2.exr",) and not session.has_capture("c2")
    monkeypatch.setattr(os, "replace", real_replace)
    assert [r.name for r in session.recover_orphans()] == ["c2"]
    assert Session.open(recorded).has_capture("c2")


def test_foreign_orphans_are_kept_not_adopted(recorded):
    imageio.write_image(recorded / "captures" / "stray.exr", _capture(4))
    session = Session.open(recorded)
    assert session.orphans == ("captures/stray.exr",)
    assert session.recover_orphans() == []
    assert session.orphans == ("captures/stray.exr",) and (recorded / "captures" / "stray.exr").exists()


def test_writes_never_leave_the_folder_through_a_symlink(recorded, tmp_path):
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    session = Session.open(recorded)
    (recorded / "calibration").rename(tmp_path / "old-calibration")
    (recorded / "calibration").symlink_to(outside)
    with pytest.raises(SessionError, match="leads outside the session folder"):
        session.write_array("newgroup", "x", np.zeros(3))
    assert list(outside.iterdir()) == []
