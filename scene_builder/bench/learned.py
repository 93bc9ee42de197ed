"""CPU time and memory of the learned perception backends at their published size:
``python -m scene_builder.bench.learned``.

No weights reach this project's machines, but compute does not depend on the weights' values:
each model is built from the published architecture (Depth Anything V2 Small: DINOv2-S/14 + DPT,
24.8 M parameters; SAM 2 Hiera-Tiny, transformers' ``Sam2Model``, the image part of the 38.9 M
checkpoint; Grounding DINO Swin-T, transformers' ``GroundingDinoConfig()`` defaults, with a BERT
tokenizer of the prompt's words) with random weights, saved, and loaded back through the
project's own backend class, then run on a real 640 x 480 photo of ``../shared/data/real``
(Grounding DINO sees it at 800 x 1066, its published input size, prompted with the whole room
vocabulary). ``--only NAME ...`` measures some of them. Each model runs in its own process
so that its peak resident memory is its own. Prints a Markdown table.

SAM 2's automatic generator is timed as its model work: the image embedding and the decoding of
upstream's full 32 x 32 point grid (16 batches of 64 points, 3 masks each). Which masks pass the
quality filters depends on the weights (random weights pass far more than real ones), so the
filtering, NMS and upsampling after it are left out.

Times are given as CPU seconds of the process (all its threads), which other load on the machine
barely changes, and as wall seconds (which it does).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
PHOTO = REPO.parent / "shared" / "data" / "real" / "nyuv2_metric3d_00000" / "rgb.jpg"


def _photo() -> np.ndarray:
    from PIL import Image

    if PHOTO.is_file():
        return np.asarray(Image.open(PHOTO).convert("RGB"))
    return np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)


def _depth_anything(folder: Path):
    import torch
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config

    from perception.learned.depth_anything import DepthAnythingV2Estimator

    backbone = Dinov2Config(hidden_size=384, num_attention_heads=6, num_hidden_layers=12, intermediate_size=1536,
                            image_size=518, patch_size=14, out_indices=[3, 6, 9, 12], reshape_hidden_states=False)
    config = DepthAnythingConfig(backbone_config=backbone, reassemble_hidden_size=384, neck_hidden_sizes=[48, 96, 192, 384],
                                 fusion_hidden_size=64, head_hidden_size=32, depth_estimation_type="metric", max_depth=20)
    torch.manual_seed(0)
    model = DepthAnythingForDepthEstimation(config)
    n = sum(p.numel() for p in model.parameters())
    model.save_pretrained(folder)
    est = DepthAnythingV2Estimator(folder, device="cpu")
    rgb = _photo()
    return n, [("Depth Anything V2 Small, metric (`depth-anything-v2`)", "one photo", lambda: est.estimate(rgb))]


def _sam2(folder: Path):
    import torch
    from transformers import Sam2Config, Sam2Model

    from perception.learned.sam2 import Sam2Segmenter

    torch.manual_seed(0)
    model = Sam2Model(Sam2Config())  # transformers' defaults are the Hiera-Tiny architecture
    n = sum(p.numel() for p in model.parameters())
    model.save_pretrained(folder)
    seg = Sam2Segmenter(folder, device="cpu")
    rgb = _photo()

    def automatic_model_work():
        from perception.learned.sam2 import point_grid

        emb, inner = seg._embed(rgb)
        grid = point_grid(seg.settings.points_per_side, rgb.shape[1], rgb.shape[0])
        for start in range(0, len(grid), seg.settings.points_per_batch):
            pts = seg._to_model_coords(grid[start : start + seg.settings.points_per_batch], rgb.shape[:2], inner)[:, None, :]
            seg._decode(emb, pts, np.ones((len(pts), 1), dtype=np.int64), multimask=True)

    boxes = np.array([[50.0, 60.0, 300.0, 400.0], [320.0, 100.0, 600.0, 420.0], [10.0, 10.0, 200.0, 150.0],
                      [400.0, 20.0, 630.0, 200.0], [200.0, 250.0, 450.0, 470.0]])
    return n, [
        ("SAM 2 Hiera-Tiny automatic masks (`sam2`), model work", "one photo, 32 x 32 points", automatic_model_work),
        ("SAM 2 Hiera-Tiny box prompts (`segment_boxes`)", "one photo, 5 boxes", lambda: seg.segment_boxes(rgb, boxes)),
    ]


def _bert_tokenizer(folder: Path, words: list[str]):
    """A BERT WordPiece tokenizer with bert-base-uncased's ids for the special tokens, "." and "?"
    (the ids Grounding DINO splits phrases at) and one token per word of ``words``: no hub here,
    and the prompt's length (about a hundred tokens) is small beside the image's."""
    from transformers import BertTokenizer

    vocab = ["[PAD]"] + [f"[unused{i}]" for i in range(99)] + ["[UNK]", "[CLS]", "[SEP]", "[MASK]"]
    vocab += [f"[unused{i}]" for i in range(99, 99 + 1012 - len(vocab))] + ["."]
    vocab += [f"[unused{i}]" for i in range(1000, 1000 + 1029 - len(vocab))] + ["?"] + words
    (folder / "vocab.txt").write_text("\n".join(vocab) + "\n")
    BertTokenizer(vocab=str(folder / "vocab.txt")).save_pretrained(folder)


def _grounding_dino(folder: Path):
    import torch
    from transformers import GroundingDinoConfig, GroundingDinoForObjectDetection

    from perception.learned.grounding_dino import GroundingDinoDetector, prompt_phrases

    torch.manual_seed(0)
    model = GroundingDinoForObjectDetection(GroundingDinoConfig())  # the defaults are grounding-dino-tiny's architecture
    n = sum(p.numel() for p in model.parameters())
    model.save_pretrained(folder)
    _bert_tokenizer(folder, sorted({w for p, _ in prompt_phrases() for w in p.split()}))
    det = GroundingDinoDetector(folder, device="cpu")  # no preprocessor_config.json: the published one
    rgb = _photo()
    tokens = sum(len(p.input_ids) for p in det.prompts)
    what = f"one photo, {len(det.phrases)} phrases in {len(det.prompts)} prompt{'s' if len(det.prompts) > 1 else ''} ({tokens} tokens)"
    return n, [("Grounding DINO Swin-T (`grounding-dino-tiny`), `detect`", what, lambda: det.detect(rgb))]


KINDS = {"depth": _depth_anything, "sam2": _sam2, "grounding-dino": _grounding_dino}


def _measure(kind: str, repeats: int, queue) -> None:
    import torch

    torch.set_num_threads(max(1, torch.get_num_threads()))
    with tempfile.TemporaryDirectory() as tmp:
        n, runs = KINDS[kind](Path(tmp))
        rows = []
        for name, what, fn in runs:
            fn()  # warm-up
            wall, cpu = [], []
            for _ in range(repeats):
                t0, c0 = time.perf_counter(), time.process_time()
                fn()
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            rows.append((name, what, statistics.median(cpu), statistics.median(wall)))
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    queue.put(json.dumps({"params_m": n / 1e6, "rows": rows, "peak_mb": peak_mb, "threads": torch.get_num_threads()}))


def main(repeats: int = 3, only: tuple[str, ...] = ()) -> None:
    """Measure every backend of :data:`KINDS` (or those of ``only``) and print the table."""
    ctx = mp.get_context("spawn")
    print(f"Median of {repeats} runs after one warm-up, CPU; peak resident memory of the process (model, activations, "
          "Python and torch).")
    print()
    print("| backend | input | params | CPU s | wall s | peak RSS MB |")
    print("|---|---|---:|---:|---:|---:|")
    for kind in only or tuple(KINDS):
        queue = ctx.Queue()
        proc = ctx.Process(target=_measure, args=(kind, repeats, queue))
        proc.start()
        out = json.loads(queue.get(timeout=3600))
        proc.join()
        for name, what, cpu, wall in out["rows"]:
            print(f"| {name} | {what} ({out['threads']} threads) | {out['params_m']:.1f} M | {cpu:.2f} | {wall:.2f} | {out['peak_mb']:.0f} |")
    print()
    print(f"Load average at the end: {os.getloadavg()[0]:.1f}.")


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="CPU time and memory of the learned backends with random weights of the published size")
    parser.add_argument("--only", nargs="+", choices=sorted(KINDS), default=(), help="measure only these backends")
    parser.add_argument("--repeats", type=int, default=3, help="runs after one warm-up (default 3)")
    args = parser.parse_args()
    main(args.repeats, tuple(args.only))
