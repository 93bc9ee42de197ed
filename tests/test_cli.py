"""The command line: instant help, and one-line errors with a non-zero exit for every bad input,
leaving no half-written output behind."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from scene_builder.cli import main

from .conftest import REPO

CLI = [sys.executable, "-m", "scene_builder.cli"]


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_help_is_fast_and_imports_no_heavy_library():
    code = (
        "import sys, scene_builder.cli as c\n"
        "heavy = [m for m in ('torch','transformers','rerun','pxr','coacd','open3d','mujoco','trimesh') if m in sys.modules]\n"
        "print(','.join(heavy))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
    res = _run(["--help"], REPO)
    assert res.returncode == 0 and "simulation-ready" in res.stdout
    help_text = " ".join(res.stdout.split())
    assert "Exit status: 0 ok, 1 other failure, 2 usage error" in help_text and "3 input error" in help_text
    res = _run(["build", "--help"], REPO)
    for flag in ("--depth", "--depth-scale", "--intrinsics", "--fov-deg", "--out", "--overwrite", "--seed", "--viz"):
        assert flag in res.stdout


@pytest.fixture()
def rgbd(tmp_path: Path) -> tuple[Path, Path]:
    rng = np.random.default_rng(0)
    img = tmp_path / "room.png"
    Image.fromarray(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)).save(img)
    depth = tmp_path / "depth.png"
    Image.fromarray(np.full((48, 64), 2000, np.uint16)).save(depth)
    return img, depth


def _bad_inputs(tmp_path: Path, img: Path, depth: Path) -> dict[str, list[str]]:
    not_image = tmp_path / "notes.jpg"
    not_image.write_text("this is not a picture")
    wrong = tmp_path / "wrong.png"
    Image.fromarray(np.full((24, 32), 2000, np.uint16)).save(wrong)
    zero = tmp_path / "zero.png"
    Image.fromarray(np.zeros((48, 64), np.uint16)).save(zero)
    nan = tmp_path / "nan.npy"
    np.save(nan, np.full((48, 64), np.nan, np.float32))
    a_file = tmp_path / "occupied"
    a_file.write_text("x")
    return {
        "missing image": [str(tmp_path / "nope.jpg")],
        "not an image": [str(not_image)],
        "missing depth": [str(img), "--depth", str(tmp_path / "nope.png")],
        "depth wrong size": [str(img), "--depth", str(wrong)],
        "all-zero depth": [str(img), "--depth", str(zero)],
        "NaN depth": [str(img), "--depth", str(nan)],
        "intrinsics not numbers": [str(img), "--depth", str(depth), "--intrinsics", "a,b,c,d"],
        "intrinsics negative focal": [str(img), "--depth", str(depth), "--intrinsics", "-5,500,32,24"],
        "output is a file": [str(img), "--depth", str(depth), "--intrinsics", "50,50,32,24", "-o", str(a_file)],
    }


def test_every_bad_input_gives_one_line_error_and_leaves_nothing(tmp_path: Path, rgbd, capsys):
    img, depth = rgbd
    cases = _bad_inputs(tmp_path, img, depth)
    before = sorted(p.name for p in tmp_path.iterdir())
    for case, args in cases.items():
        try:
            code = main([*args, "-q"])
        except SystemExit as exc:  # argparse rejects malformed flags itself
            code = exc.code
        assert code != 0, case
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, f"{case}: expected one line, got {err}"
        assert err[0].startswith("error: "), f"{case}: {err[0]}"
    after = sorted(p.name for p in tmp_path.iterdir())
    assert after == before, "a failed build left files behind"


def test_check_rejects_a_folder_that_is_not_an_output(tmp_path: Path, capsys):
    code = main(["check", str(tmp_path / "missing")])
    assert code != 0
    assert capsys.readouterr().err.startswith("error:")


def test_report_keys_written_by_a_real_build(tmp_path: Path):
    """A tiny synthetic RGB-D image of a box on a floor builds end to end."""
    from scene_builder.bench.render import write_demo_input

    sample = write_demo_input(tmp_path / "room", seed=1, n_objects=3)
    cam = json.loads((sample / "camera.json").read_text())
    out = tmp_path / "out"
    code = main(
        [
            str(sample / "rgb.png"),
            "--depth",
            str(sample / "depth.png"),
            "--intrinsics",
            f"{cam['fx']},{cam['fy']},{cam['cx']},{cam['cy']}",
            "-o",
            str(out),
            "-q",
            "--viz",
            "off",
        ]
    )
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    for key in ("timings_s", "objects", "layout", "backends"):
        assert key in report
    assert report["timings_s"]["total"] > 0
    assert {"max_penetration_m", "settle_max_drift_m"} <= set(report["layout"])
    for name in ("scene.xml", "scene.usda", "scene.json", "scene.sdf", "urdf/placements.json", "scene.glb"):
        assert (out / name).is_file(), name
