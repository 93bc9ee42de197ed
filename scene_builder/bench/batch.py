"""Batch throughput: N photos through ``scene-builder batch`` with 1 and 2 local workers and on a
local Ray cluster, and what that means for 10,000 photos on 100 nodes.

Run: ``python -m scene_builder.bench.batch [--data ../shared/data/real] [--n 20] [--width 320]
[--workers 1,2] [--no-ray] [--no-full-size]``.

Inputs: the real RGB-D samples with intrinsics (``DATA/*/rgb.* + depth.png + camera.json``),
cycled to N items and downscaled to ``--width`` pixels wide (depth nearest-neighbour, intrinsics
scaled; :func:`write_small_sample`): a full-size real photo takes 30-45 s on these 2 cores, so
N of them three times over would take most of an hour. One full-size photo is built once, alone,
to scale the figures back up. Every configuration builds the same items into a fresh OUT_ROOT
with the CLI's defaults (offline: sensor depth, the best segmentation available without weights).
The machine is shared: the 1-minute load average before and after each run is printed beside it.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
from pathlib import Path

__all__ = ["main", "write_small_sample", "rgbd_samples"]

DEFAULT_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real"


def rgbd_samples(data: Path) -> list[Path]:
    """Sample folders of ``data`` with an RGB photo, an aligned-size depth.png and camera.json."""
    return sorted(d for d in Path(data).iterdir() if d.is_dir() and (d / "depth.png").is_file() and (d / "camera.json").is_file())


def write_small_sample(src: Path, dst: Path, width: int) -> Path:
    """A copy of the sample folder ``src`` at ``width`` pixels wide in ``dst``: rgb.png (bilinear),
    depth.png (nearest neighbour, still uint16 millimetres) and camera.json with the intrinsics
    scaled (pixel centres kept: c' = (c + 0.5) s - 0.5)."""
    from PIL import Image

    dst.mkdir(parents=True, exist_ok=True)
    rgb_path = next(p for p in (src / "rgb.jpg", src / "rgb.png") if p.is_file())
    with Image.open(rgb_path) as im:
        rgb = im.convert("RGB")
    w0, h0 = rgb.size
    s = width / w0
    size = (width, max(1, round(h0 * s)))
    rgb.resize(size, Image.BILINEAR).save(dst / "rgb.png")
    with Image.open(src / "depth.png") as depth:
        depth.resize(size, Image.NEAREST).save(dst / "depth.png")
    cam = json.loads((src / "camera.json").read_text())
    scaled = {"fx": cam["fx"] * s, "fy": cam["fy"] * s, "cx": (cam["cx"] + 0.5) * s - 0.5, "cy": (cam["cy"] + 0.5) * s - 0.5}
    (dst / "camera.json").write_text(json.dumps({**scaled, "width": size[0], "height": size[1]}) + "\n")
    return dst


def _load() -> float:
    return os.getloadavg()[0]


def _run(source: Path, out: Path, workers: int, ray: str | None):
    from scene_builder.batch import BatchOptions, run_batch
    from scene_builder.config import BuildConfig

    before = _load()
    summary = run_batch(source, out, BuildConfig(), BatchOptions(workers=workers, ray=ray, progress=False))
    return summary, before, _load()


def _full_size(sample: Path, tmp: Path) -> tuple[float, float | None]:
    """Seconds of one build of a full-size real photo (a 1-worker batch of one item) and the
    worker's peak resident memory in MB."""
    listing = tmp / "full.txt"
    listing.write_text(f"{sample}\n")
    summary, _, _ = _run(listing, tmp / "out-full", 1, None)
    if summary.done != 1 or summary.median_build_s is None:
        raise SystemExit(f"the full-size build of {sample} failed: {summary.errors}")
    return summary.median_build_s, summary.peak_worker_rss_mb


def _fmt(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of RGB-D sample folders")
    parser.add_argument("--n", type=int, default=20, help="photos per configuration")
    parser.add_argument("--width", type=int, default=320, help="width the photos are downscaled to")
    parser.add_argument("--workers", default="1,2", help="local worker counts, comma-separated")
    parser.add_argument("--ray-cpus", type=int, default=2, help="CPUs of the local Ray cluster (0: no Ray run)")
    parser.add_argument("--no-full-size", action="store_true", help="skip the full-size reference build")
    args = parser.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    samples = rgbd_samples(args.data)
    if not samples:
        raise SystemExit(f"no RGB-D samples with camera.json under {args.data}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp_name:
        tmp = Path(tmp_name)
        source = tmp / "photos"
        for i in range(args.n):
            write_small_sample(samples[i % len(samples)], source / f"{i:02d}_{samples[i % len(samples)].name}", args.width)
        configs = [(f"local, {w} worker{'s' if w > 1 else ''}", w, None) for w in (int(x) for x in args.workers.split(","))]
        if args.ray_cpus > 0:
            configs.append((f"Ray, local cluster (ray.init(num_cpus={args.ray_cpus}))", args.ray_cpus, "local"))
        for label, workers, ray in configs:
            summary, before, after = _run(source, tmp / f"out-{len(rows)}", workers, ray)
            rows.append((label, workers, summary, before, after))
            if ray is not None:
                import ray as ray_module

                ray_module.shutdown()
        full = None if args.no_full_size else _full_size(samples[0], tmp)
    _print(args, samples, rows, full)


def _print(args, samples: list[Path], rows, full: tuple[float, float | None] | None) -> None:
    print(
        f"{args.n} photos ({len(samples)} real RGB-D samples of `../shared/data/real` cycled, downscaled to {args.width} px wide), "
        "default build options offline (sensor depth, rerun recording saved). `wall` counts from the first item submitted "
        "to the last result, starting the workers (and the Ray cluster) included. `overhead` is the median per item of the "
        "coordinator's time from submit to result minus the build's own total. `warm-up`: seconds a worker spends loading "
        "the stages and their libraries before its first photo. `peak RSS`: the largest resident memory of a worker.\n"
    )
    print("| configuration | done / failed | wall s | scenes / min | median build s | overhead s / item | warm-up s | peak RSS / worker MB | load avg (1 min) before → after |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, _workers, s, before, after in rows:
        print(
            f"| {label} | {s.done} / {s.failed} | {s.wall_s:.1f} | {s.scenes_per_min:.2f} | {_fmt(s.median_build_s, '.2f')} | "
            f"{_fmt(s.overhead_s, '.3f')} | {_fmt(s.warm_s, '.1f')} | {_fmt(s.peak_worker_rss_mb, '.0f')} | {before:.2f} → {after:.2f} |"
        )
    print(f"\nMachine: {os.cpu_count()} cores, shared with other jobs (load averages above).")
    if full is None:
        return
    full_s, full_rss = full
    one = next((s for label, w, s, *_ in rows if w == 1 and "local" in label), None)
    if one is None or one.median_build_s is None:
        return
    best_label, _, best, *_ = max(rows, key=lambda r: r[2].scenes_per_min)
    cores = os.cpu_count() or 2
    small_s = one.median_build_s
    scale = full_s / small_s  # a full-size build costs this many small ones (both alone, 1 worker)
    node_rate = best.scenes_per_min / scale  # full-size scenes per minute of one node, as measured here
    minutes = 10_000 / (100 * node_rate)
    overhead = statistics.median([s.overhead_s for _, _, s, *_ in rows if s.overhead_s is not None] or [0.0])
    ideal_rate = cores * 60.0 / (full_s + overhead)  # every core a worker at the 1-worker speed
    peak = max((s.peak_worker_rss_mb or 0) for _, _, s, *_ in rows)
    slower = any(w > 1 and s.scenes_per_min < one.scenes_per_min * w for _, w, s, *_ in rows)
    caveat = ", and the runs with more workers above did not reach it on this shared machine" if slower else ""
    print(
        f"\nOne full-size photo ({samples[0].name}, alone, 1 worker): {full_s:.1f} s of build, {scale:.2f} x the "
        f"{small_s:.2f} s of a {args.width} px photo, peak worker memory {_fmt(full_rss, '.0f')} MB.\n\n"
        f"**10,000 photos on 100 nodes like this one** ({cores} cores each). As measured here: the best configuration "
        f"({best_label}) built {best.scenes_per_min:.2f} scenes/min at {args.width} px, so {best.scenes_per_min:.2f} / "
        f"{scale:.2f} = {node_rate:.2f} full-size scenes/min per node; 100 nodes make {100 * node_rate:.0f} scenes/min and "
        f"10,000 photos take 10,000 / {100 * node_rate:.0f} = {minutes:.0f} min ({100 * minutes / 60:.0f} node-hours). "
        f"On dedicated nodes where each core runs one worker at the 1-worker speed measured here (an upper bound: that "
        f"worker had the torch threads of every core{caveat}): {cores} x 60 / ({full_s:.1f} + {overhead:.2f} s overhead) = "
        f"{ideal_rate:.2f} scenes/min per node, 10,000 / {100 * ideal_rate:.0f} = {10_000 / (100 * ideal_rate):.0f} min. "
        f"Per item, the batch adds {overhead:.2f} s ({100 * overhead / full_s:.1f} % of a full-size build) and each worker "
        f"loads for about {_fmt(one.warm_s, '.0f')} s once; the coordinator records "
        f"{100 * node_rate / 60:.1f} items/s, one SQLite transaction each. Memory: a worker reached {peak:.0f} MB "
        f"after {args.n} photos in a row, so budget about {peak / 1000:.0f} GB per worker (or cap it with --max-worker-memory-gb / "
        "--max-items-per-worker)."
    )

if __name__ == "__main__":
    main()
