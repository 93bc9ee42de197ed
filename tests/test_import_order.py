"""Process-level import order of the native libraries a build loads.

onnxruntime (the offline detectors) crashes the process with SIGSEGV when it is imported after
coacd (convex decomposition). A batch worker imports every stage before its first photo
(``pipeline.load_stages``), and any process may generate an asset before it first detects:
both must then still run a detector.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_detector_runs_after_the_stages_are_loaded():
    code = (
        "import numpy as np\n"
        "from scene_builder.pipeline import load_stages\n"
        "load_stages(threads=1)\n"
        "import onnxruntime\n"
        "print('loaded', onnxruntime.__version__)\n"
    )
    res = _run(code)
    assert res.returncode == 0, f"exit {res.returncode}: {res.stderr[-2000:]}"
    assert "loaded" in res.stdout


def test_coacd_through_the_project_then_onnxruntime():
    code = (
        "from generation.collision import import_coacd\n"
        "coacd = import_coacd()\n"
        "import onnxruntime\n"
        "print('ok', coacd.__name__)\n"
    )
    res = _run(code)
    assert res.returncode == 0, f"exit {res.returncode}: {res.stderr[-2000:]}"
    assert "ok coacd" in res.stdout
