"""Weights when a network is there: the download path against a local HTTP server in the hub's
layout (HF_ENDPOINT) serving tiny random Depth Anything V2, SAM 2 and Grounding DINO models, the
build's first-run preparation (download once, then the learned backends answer: Grounding DINO's
boxes prompt SAM 2), and the offline behaviour (one line naming the fallback and why, decided in
seconds, no request sent; the offline detectors answer and report.json says so)."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from perception import models
from perception.backends import build_registries, prepare_learned_weights
from scene_builder.config import PerceptionConfig
from tests.local_hub import LocalHub

DA = models.default_model("depth")
SAM = models.default_model("segmentation")
GD = models.default_model("detection")
#: What a first build downloads when no depth map is given: Depth Anything V2, SAM 2, Grounding DINO.
ALL_MB = round(DA.download_mb + SAM.download_mb + GD.download_mb)


@pytest.fixture(scope="module")
def repos(tmp_path_factory) -> dict[str, Path]:
    from tests.test_learned_depth_anything import _tiny
    from tests.test_learned_grounding_dino import save_tiny_grounding_dino
    from tests.test_learned_sam2 import save_tiny_sam2

    root = tmp_path_factory.mktemp("hub")
    return {DA.repo_id: _tiny(root, name="da"), SAM.repo_id: save_tiny_sam2(root / "sam"),
            GD.repo_id: save_tiny_grounding_dino(root / "gd")}


@pytest.fixture()
def hub(repos):
    with LocalHub(repos) as h:
        yield h


@pytest.fixture()
def online(hub, monkeypatch, tmp_path):
    """This process talks to the local hub: HF_ENDPOINT set, offline mode off, an empty cache."""
    import huggingface_hub.constants as hf_constants

    monkeypatch.setenv("HF_ENDPOINT", hub.url)
    monkeypatch.setenv("HF_HUB_OFFLINE", "0")
    monkeypatch.setattr(hf_constants, "HF_HUB_OFFLINE", False)
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_cache"))
    monkeypatch.delenv(models.ENV_MODELS_DIR, raising=False)
    return hub


def _child_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("HF_") and k != models.ENV_MODELS_DIR}
    env.update(extra)
    return env


@pytest.mark.slow
def test_models_fetch_downloads_from_the_hub_layout_with_a_progress_bar(hub, tmp_path):
    """The real command in a fresh process: ``scene-builder models fetch`` with no names gets the
    three models a build uses; the weights then load and run."""
    target = tmp_path / "models"
    res = subprocess.run(
        [sys.executable, "-m", "scene_builder.cli", "models", "fetch", "--models-dir", str(target)],
        capture_output=True, text=True, timeout=300,
        env=_child_env(HF_ENDPOINT=hub.url, HF_HOME=str(tmp_path / "hf_home"), PYTHONPATH=os.environ.get("PYTHONPATH", "")),
    )
    assert res.returncode == 0, res.stderr[-2000:]
    printed = [Path(line) for line in res.stdout.split()]
    assert printed == [target / m.name for m in (DA, SAM, GD)]
    assert "100%" in res.stderr or "complete" in res.stderr.lower()  # huggingface_hub's progress bars
    served = {p for m, p in hub.requests if m == "GET" and p.endswith("/model.safetensors")}
    assert served == {f"/{m.repo_id}/resolve/{hub.commits[m.repo_id]}/model.safetensors" for m in (DA, SAM, GD)}
    for m in (DA, SAM, GD):
        assert models.resolve_weights(m.name, target) == target / m.name

    from perception.learned.depth_anything import DepthAnythingV2Estimator
    from perception.learned.sam2 import Sam2Segmenter

    rgb = np.random.default_rng(0).integers(0, 255, (30, 40, 3), dtype=np.uint8)
    assert DepthAnythingV2Estimator(target / DA.name, device="cpu").estimate(rgb).depth_m.shape == (30, 40)
    assert Sam2Segmenter(target / SAM.name, device="cpu").segment_boxes(rgb, np.array([[1.0, 1.0, 20.0, 20.0]])).shape == (1, 30, 40)
    from perception.learned.grounding_dino import GroundingDinoDetector

    boxes = GroundingDinoDetector(target / GD.name, device="cpu").detect(rgb).boxes_xyxy_px
    assert len(boxes) and np.all(boxes[:, 2] <= 40) and np.all(boxes[:, 3] <= 30)


@pytest.mark.slow
def test_a_build_downloads_once_then_the_learned_backends_answer(online, tmp_path):
    config = PerceptionConfig(models_dir=tmp_path / "models")
    before = build_registries(config)
    assert before.depth.resolve()[1].backend == "single-view-geometry"
    notes = prepare_learned_weights(config, need_depth=True, progress=False)
    assert len(notes) == 1 and notes[0].startswith(f"downloaded {DA.name}, {SAM.name}, {GD.name} (about {ALL_MB} MB)")
    after = build_registries(config)
    depth, use = after.depth.resolve()
    assert use.backend == "depth-anything-v2" and use.reason == "best available"
    assert depth.estimate(np.zeros((20, 30, 3), np.uint8)).depth_m.shape == (20, 30)
    # Grounding DINO's boxes prompt SAM 2 (Grounded-SAM-2): the detection-driven segmenter answers
    seg, use = after.segmentation.resolve()
    # ... beside the bundled closed-vocabulary detectors (their boxes are merged after its own)
    assert use.backend == "detections" and [d.name for d in seg.detectors] == [GD.name, "centernet-mbv3-coco", "ssd-mobilenet-oid"]
    assert seg.box_segmenter.name == "sam2"
    # the second run finds them: nothing is asked of the hub
    n = len(online.requests)
    assert prepare_learned_weights(config, need_depth=True, progress=False) == ()
    assert len(online.requests) == n


def test_a_failed_download_leaves_the_build_on_its_fallbacks_and_says_why(online, monkeypatch, tmp_path):
    """The hub answers but lacks the repo (huggingface_hub's RepositoryNotFoundError, an OSError),
    or goes away between the reachability check and the download: one note each naming the
    fallback and the cause, never a traceback."""
    config = PerceptionConfig(models_dir=tmp_path / "models")
    online.repos.pop(SAM.repo_id)
    (line,) = prepare_learned_weights(config, need_depth=False, progress=False)
    assert line.startswith(f"no {SAM.name} or {GD.name} weights here and no download (download failed: RepositoryNotFoundError")
    assert "segmentation: " in line and "instead of sam2" in line and "\n" not in line
    monkeypatch.setenv("HF_ENDPOINT", f"http://127.0.0.1:{_closed_port()}")
    monkeypatch.setattr(models, "offline_reason", lambda *a, **k: None)  # it was reachable a moment ago
    (line,) = prepare_learned_weights(config, need_depth=False, progress=False)
    assert line.startswith(f"no {SAM.name} or {GD.name} weights here and no download (download failed: ")


def test_sensor_depth_needs_no_depth_model(online, tmp_path):
    config = PerceptionConfig(models_dir=tmp_path / "models")
    notes = prepare_learned_weights(config, need_depth=False, progress=False)
    assert notes[0].startswith(f"downloaded {SAM.name}, {GD.name} ")
    assert models.resolve_weights(DA.name, config.models_dir) is None
    # a user who chose the geometric backends downloads nothing
    quiet = PerceptionConfig(models_dir=tmp_path / "other", depth_backend="single-view-geometry", segmentation_backend="depth-clusters")
    assert prepare_learned_weights(quiet, need_depth=True, progress=False) == ()


def test_offline_says_which_fallback_and_why_in_one_line_without_asking_the_hub(hub, monkeypatch, tmp_path):
    monkeypatch.setenv("HF_ENDPOINT", hub.url)
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    config = PerceptionConfig(models_dir=tmp_path / "models")
    regs = build_registries(config)
    depth_fallback = next(e.name for e in regs.depth.entries() if e.available() is None)
    seg_fallback = next(e.name for e in regs.segmentation.entries() if e.available() is None)
    (line,) = prepare_learned_weights(config, need_depth=True)
    assert "\n" not in line and "HF_HUB_OFFLINE" in line
    assert f"depth: {depth_fallback} instead of depth-anything-v2" in line
    assert f"segmentation: {seg_fallback} instead of sam2" in line
    # The bundled offline detectors answer in Grounding DINO's place.
    assert f"detection: centernet-mbv3-coco+ssd-mobilenet-oid instead of {GD.name}" in line
    assert "scene-builder models fetch" in line and f"{ALL_MB} MB" in line
    monkeypatch.setenv("HF_HUB_OFFLINE", "0")
    (line,) = prepare_learned_weights(config, need_depth=True, offline=True)
    assert "(--offline)" in line
    assert hub.requests == []  # offline means offline


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_no_network_is_found_out_in_seconds(monkeypatch, tmp_path):
    monkeypatch.setenv("HF_HUB_OFFLINE", "0")
    for endpoint, cause in ((f"http://127.0.0.1:{_closed_port()}", "ConnectionRefusedError"), ("https://hub.invalid", "gaierror")):
        monkeypatch.setenv("HF_ENDPOINT", endpoint)
        t0 = time.monotonic()
        why = models.offline_reason(timeout_s=2.0)
        assert time.monotonic() - t0 < 10.0  # a guard against hanging, not a timing test
        assert why is not None and cause in why
        (line,) = prepare_learned_weights(PerceptionConfig(models_dir=tmp_path), need_depth=False)
        assert line.startswith(f"no {SAM.name} or {GD.name} weights here and no download (cannot reach")


def _demo_build_args(tmp_path: Path, models_dir: Path) -> tuple[list[str], Path]:
    """CLI arguments building a rendered two-object room (RGB-D: no depth model needed)."""
    from scene_builder.bench.render import write_demo_input

    sample = write_demo_input(tmp_path / "room", seed=1, n_objects=2)
    cam = json.loads((sample / "camera.json").read_text())
    intr = ",".join(str(cam[k]) for k in ("fx", "fy", "cx", "cy"))
    out = tmp_path / "out"
    args = ["build", str(sample / "rgb.png"), "--depth", str(sample / "depth.png"), "--intrinsics", intr, "--viz", "off",
            "--no-usd", "--no-urdf", "--no-sdf", "--no-gltf", "-o", str(out), "--models-dir", str(models_dir)]
    return args, out


def _offline_detector_files(folder: Path) -> Path:
    """A models dir holding only the shared offline detector files (links)."""
    from tests.conftest import MODELS, require

    folder.mkdir(parents=True)
    for f in sorted(require(MODELS).iterdir()):
        if f.is_file() and f.suffix != ".md":
            (folder / f.name).symlink_to(f)
    return folder


@pytest.mark.slow
def test_build_offline_prints_one_line_and_builds_with_the_fallbacks(tmp_path, capsys):
    """Offline with only the offline detector files: one line names each fallback, the offline
    detectors answer in place of Grounding DINO and report.json says so."""
    from scene_builder.cli import main

    args, out = _demo_build_args(tmp_path, _offline_detector_files(tmp_path / "offline_models"))
    assert main(args + ["--offline"]) == 0
    err = capsys.readouterr().err.splitlines()
    notes = [ln for ln in err if "no download" in ln]
    assert len(notes) == 1 and notes[0].startswith(f"no {SAM.name} or {GD.name} weights here and no download (--offline)")
    report = json.loads((out / "report.json").read_text())
    uses = {b["task"]: b for b in report["backends"]}
    assert f"{uses['segmentation']['backend']} instead of sam2" in notes[0]
    assert uses["segmentation"]["backend"] == "detections"
    assert uses["detection"]["backend"] == "centernet-mbv3-coco+ssd-mobilenet-oid"
    assert f"detection: centernet-mbv3-coco+ssd-mobilenet-oid instead of {GD.name}" in notes[0]
    assert uses["box-segmentation"]["backend"] == "grabcut"


@pytest.mark.slow
def test_a_networked_build_downloads_grounding_dino_and_its_boxes_prompt_sam2(online, tmp_path, capsys):
    """The first build on a networked machine (the local hub): SAM 2 and Grounding DINO are
    downloaded (no depth model: the depth map is given), the detection-driven segmenter runs
    Grounding DINO's boxes through SAM 2, and report.json names both."""
    from scene_builder.cli import main

    args, out = _demo_build_args(tmp_path, tmp_path / "models")
    assert main(args) == 0
    err = capsys.readouterr().err.splitlines()
    assert any(ln.startswith(f"downloaded {SAM.name}, {GD.name} ") for ln in err), err[-5:]
    report = json.loads((out / "report.json").read_text())
    uses = {b["task"]: b for b in report["backends"]}
    assert uses["segmentation"]["backend"] == "detections"
    assert uses["detection"]["backend"] == f"{GD.name}+centernet-mbv3-coco+ssd-mobilenet-oid" and f"before merging: {GD.name} " in uses["detection"]["reason"]
    assert uses["box-segmentation"]["backend"] == "sam2"
    served = {p for m, p in online.requests if m == "GET" and p.endswith("/model.safetensors")}
    assert served == {f"/{m.repo_id}/resolve/{online.commits[m.repo_id]}/model.safetensors" for m in (SAM, GD)}
