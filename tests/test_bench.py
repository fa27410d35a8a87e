"""The benchmarks still run: each imports, and the quick ones finish on tiny inputs.

Nothing here times anything (the benchmarks print their own figures); a benchmark that no
longer imports or runs is a broken measuring tool, and README's numbers come from them.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"
QUICK = {
    "denoise.py": ["--height", "64", "--width", "96", "--order", "3"],
    "graycode.py": ["--camera", "24x32", "--projector", "32x64", "--repeat", "1"],
    "recolor.py": ["--megapixels", "0.05", "--order", "2"],
    "solve.py": ["--size", "40", "40", "--scipy-columns", "50", "--skip-full"],
    "preview.py": ["--height", "1440", "--width", "2560", "--order", "2", "--events", "3"],
    "overlay.py": ["--size", "64", "--moves", "12", "--brush", "8"],
    "trusted.py": ["--size", "32", "40", "--order", "2", "--repeats", "1"],
    "refine.py": ["--quick"],
}


@pytest.mark.parametrize("name", sorted(p.name for p in BENCH.glob("*.py")))
def test_benchmark_imports(name):
    """Every benchmark's imports resolve against the current code (its main is not run)."""
    code = f"import runpy; runpy.run_path({str(BENCH / name)!r}, run_name='bench_import_check')"
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]


@pytest.mark.parametrize("name", sorted(QUICK))
def test_quick_benchmark_runs(name, tmp_path):
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    done = subprocess.run([sys.executable, str(BENCH / name), *QUICK[name]], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=240)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "x" in done.stdout  # every benchmark prints its ratios against the alternative


def test_albedit_bench_offers_every_benchmark():
    from app.cli.bench import NAMES

    assert set(NAMES) == {p.stem for p in BENCH.glob("*.py")}
