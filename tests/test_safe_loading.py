"""Model files are loaded only with safe loaders (issue 12): safetensors, ``torch.load(...,
weights_only=True)``, numpy without pickles. A pickled checkpoint can run code when loaded.

Checked on the source of every package (an AST walk: a new loader that forgets the flag fails
here), and on a real load: a folder holding only a pickled ``pytorch_model.bin`` is refused."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from .conftest import REPO

PACKAGES = ("scene_builder", "perception", "generation", "layout", "exporters")
#: from_pretrained of these load no weights (text / JSON configs only).
NO_WEIGHTS = ("Tokenizer", "Processor", "ImageProcessor", "Config", "TransformersQwenVL")


def _calls():
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            tree = ast.parse(path.read_text(), filename=str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.Call):
                    yield path.relative_to(REPO), node


def _keyword(call: ast.Call, name: str):
    for kw in call.keywords:
        if kw.arg == name:
            return kw.value
    return None


def _is_true(node) -> bool:
    return isinstance(node, ast.Constant) and node.value is True


def _dotted(node) -> str:
    if isinstance(node, ast.Attribute):
        return f"{_dotted(node.value)}.{node.attr}"
    if isinstance(node, ast.Name):
        return node.id
    return "?"


def test_every_loader_in_the_source_is_safe():
    unsafe = []
    for path, call in _calls():
        name = _dotted(call.func)
        where = f"{path}:{call.lineno} {name}"
        if name.endswith("torch.load") and not _is_true(_keyword(call, "weights_only")):
            unsafe.append(f"{where}: needs weights_only=True")
        elif name.split(".")[-1] in ("load", "loads") and name.split(".")[0] in ("pickle", "cPickle", "dill", "joblib"):
            unsafe.append(f"{where}: pickle")
        elif name in ("np.load", "numpy.load") and _is_true(_keyword(call, "allow_pickle")):
            unsafe.append(f"{where}: allow_pickle=True")
        elif name.endswith(".from_pretrained"):
            owner = name.rsplit(".", 1)[0].split(".")[-1]
            if not any(word in owner for word in NO_WEIGHTS) and not _is_true(_keyword(call, "use_safetensors")):
                unsafe.append(f"{where}: needs use_safetensors=True")
    assert not unsafe, unsafe


def test_a_pickled_checkpoint_is_refused(tmp_path: Path):
    """transformers with use_safetensors=True refuses a folder whose only weights are a pickle."""
    torch = pytest.importorskip("torch")
    transformers = pytest.importorskip("transformers")
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation

    config = DepthAnythingConfig(
        backbone_config={"model_type": "dinov2", "hidden_size": 32, "num_hidden_layers": 2, "num_attention_heads": 2,
                         "intermediate_size": 64, "image_size": 56, "patch_size": 14, "out_features": ["stage1", "stage2"]},
        reassemble_hidden_size=32, neck_hidden_sizes=[16, 32], fusion_hidden_size=16, head_hidden_size=8,
    )
    model = DepthAnythingForDepthEstimation(config)
    config.save_pretrained(tmp_path)
    torch.save(model.state_dict(), tmp_path / "pytorch_model.bin")  # a pickle: what must not be loaded
    with pytest.raises((OSError, EnvironmentError, ValueError)):
        DepthAnythingForDepthEstimation.from_pretrained(tmp_path, use_safetensors=True)
    assert transformers.__version__
