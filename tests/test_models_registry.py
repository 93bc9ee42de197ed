"""The model registry: local resolution in every supported layout, offline fetch errors, and the
backends registered for perception."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from perception import models
from perception.learned import register_backends
from scene_builder.config import PerceptionConfig
from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.registry import Registry
from tests.conftest import MODELS, require


@pytest.fixture(autouse=True)
def _offline(monkeypatch, tmp_path):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_hf_cache"))
    monkeypatch.delenv(models.ENV_MODELS_DIR, raising=False)


def _fake_hf_folder(folder: Path) -> Path:
    folder.mkdir(parents=True)
    (folder / "config.json").write_text("{}")
    (folder / "model.safetensors").write_bytes(b"\0")
    return folder


def test_every_model_has_a_licence_task_and_files():
    names = [m.name for m in models.MODELS]
    assert len(set(names)) == len(names)
    for m in models.MODELS:
        assert m.license and m.task and m.files
    # The defaults are the permissively licensed ones.
    for task in {m.task for m in models.MODELS}:
        assert models.default_model(task).license in ("Apache-2.0", "MIT")
    assert models.model_spec("depth-anything-v2-metric-indoor-large").license == "CC-BY-NC-4.0"


def test_resolves_folder_per_model_and_hf_repo_layouts(tmp_path):
    name = "depth-anything-v2-metric-indoor-small"
    assert models.resolve_weights(name, tmp_path) is None
    partial = tmp_path / name
    partial.mkdir()
    (partial / "config.json").write_text("{}")
    assert models.resolve_weights(name, tmp_path) is None  # weights file missing
    (partial / "model.safetensors").write_bytes(b"\0")
    assert models.resolve_weights(name, tmp_path) == partial

    repo_dir = _fake_hf_folder(tmp_path / "facebook" / "sam2-hiera-tiny-hf")
    assert models.resolve_weights("sam2-hiera-tiny", tmp_path) == repo_dir


def test_environment_variable_is_the_models_dir(tmp_path, monkeypatch):
    folder = _fake_hf_folder(tmp_path / "sam2-hiera-small")
    assert models.resolve_weights("sam2-hiera-small") is None
    monkeypatch.setenv(models.ENV_MODELS_DIR, str(tmp_path))
    assert models.resolve_weights("sam2-hiera-small") == folder


def test_single_file_models_resolve_in_the_shared_models_folder():
    shared = require(MODELS)
    hit = models.resolve_weights("ssd-mobilenet-oid", shared)
    assert hit is not None and hit.name.endswith(".tflite") and hit.is_file()
    assert models.resolve_weights("deeplabv3-mnv2-pascal", shared) == shared / "deeplabv3_mnv2_pascal_quant.tflite"


def test_list_models_reports_reasons_and_locations(tmp_path):
    _fake_hf_folder(tmp_path / "sam2-hiera-tiny")
    status = {s.name: s for s in models.list_models(tmp_path)}
    assert set(status) == {m.name for m in models.MODELS}
    assert status["sam2-hiera-tiny"].available and status["sam2-hiera-tiny"].location == tmp_path / "sam2-hiera-tiny"
    da = status["depth-anything-v2-metric-indoor-small"]
    assert not da.available and da.location is None
    assert "scene-builder models fetch depth-anything-v2-metric-indoor-small" in da.reason
    assert "\n" not in da.reason


def test_fetch_offline_fails_fast_with_one_actionable_line(tmp_path):
    t0 = time.monotonic()
    with pytest.raises(ModelUnavailableError) as err:
        models.fetch_models(["depth-anything-v2-metric-indoor-small"], tmp_path)
    assert time.monotonic() - t0 < 30.0  # a guard against hanging, not a timing test
    msg = str(err.value)
    assert "\n" not in msg and "depth-anything-v2-metric-indoor-small" in msg
    assert "scene-builder models fetch depth-anything-v2-metric-indoor-small" in msg


def test_fetch_returns_present_models_without_network(tmp_path):
    folder = _fake_hf_folder(tmp_path / "sam2-hiera-tiny")
    assert models.fetch_models(["sam2-hiera-tiny"], tmp_path) == (folder,)
    with pytest.raises(InputError):
        models.fetch_models(["no-such-model"], tmp_path)


def test_register_backends_names_priorities_and_availability(tmp_path):
    depth, seg, naming = Registry("depth"), Registry("segmentation"), Registry("naming")
    register_backends(depth, seg, naming, PerceptionConfig(models_dir=tmp_path))
    assert depth.names() == ["depth-anything-v2", "single-view-geometry"]
    entries = {e.name: e for e in depth.entries() + seg.entries() + naming.entries()}
    assert entries["depth-anything-v2"].priority == 100 and entries["single-view-geometry"].priority == 0
    assert entries["sam2"].priority == 100 and entries["efficientnet-lite0"].priority == 50
    assert "models fetch" in entries["depth-anything-v2"].available()
    assert entries["sam2"].available() is not None
    assert entries["single-view-geometry"].available() is None
    backend, use = depth.resolve()
    assert use.backend == "single-view-geometry" and "depth-anything-v2" in use.reason
    assert hasattr(backend, "estimate")


# -- the offline models shipped with the project ------------------------------------------------

BUNDLED = [m for m in models.MODELS if m.bundled]


def test_bundled_models_resolve_with_no_models_dir(monkeypatch):
    """A fresh clone detects: every bundled model resolves from the package folder, with no flag
    and no environment variable, and each file has the SHA-256 its README states."""
    import hashlib
    import re

    monkeypatch.delenv(models.ENV_MODELS_DIR, raising=False)
    assert {m.name for m in BUNDLED} >= {"centernet-mbv3-coco", "ssd-mobilenet-oid", "deeplabv3-mnv2-pascal"}
    readme = (models.BUNDLED_DIR / "README.md").read_text()
    for m in BUNDLED:
        path = models.resolve_weights(m.name, None)
        assert path == models.BUNDLED_DIR / m.files[0], (m.name, path)
        assert models.unavailable_reason(m.name, None) is None
        for f in m.files:
            digest = hashlib.sha256((models.BUNDLED_DIR / f).read_bytes()).hexdigest()
            row = next(line for line in readme.splitlines() if line.startswith(f"| `{f}`"))
            assert digest in row, f"{f}: README row does not state its SHA-256 {digest}"
            assert re.search(r"LICENSES/[\w.-]+\.txt", row) or "Apache-2.0" in row
    for lic in ("human-models-MIT.txt", "Apache-2.0.txt"):
        assert (models.BUNDLED_DIR / "LICENSES" / lic).stat().st_size > 500


def test_models_dir_overrides_a_bundled_file(tmp_path):
    name = "centernet-mbv3-coco"
    copy = tmp_path / "centernet_mbv3_coco.onnx"
    copy.write_bytes((models.BUNDLED_DIR / "centernet_mbv3_coco.onnx").read_bytes())
    assert models.resolve_weights(name, tmp_path) == copy


def test_a_damaged_bundled_file_is_unavailable_with_the_reason(tmp_path, monkeypatch):
    import shutil

    folder = tmp_path / "offline_models"
    shutil.copytree(models.BUNDLED_DIR, folder)
    # What a clone without Git LFS would hold instead of the weights: a short text pointer.
    (folder / "centernet_mbv3_coco.onnx").write_text("version https://git-lfs.github.com/spec/v1\noid sha256:0\nsize 1\n")
    monkeypatch.setattr(models, "BUNDLED_DIR", folder)
    models._bundled_sums.cache_clear()
    try:
        assert models.resolve_weights("centernet-mbv3-coco", None) is None
        why = models.unavailable_reason("centernet-mbv3-coco", None)
        assert why is not None and "SHA-256" in why and "centernet_mbv3_coco.onnx" in why
        # The intact files still resolve.
        assert models.resolve_weights("ssd-mobilenet-oid", None) == folder / "object_detection_ssd_mobilenetv2_oidv4_fp16.tflite"
    finally:
        models._bundled_sums.cache_clear()
