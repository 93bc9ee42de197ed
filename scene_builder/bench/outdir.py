"""What the output folder's marker costs: hashing every file a build wrote, on real builds.

Run: ``python -m scene_builder.bench.outdir [--data ../shared/data] [--samples N]``.

The first ``N`` (default 3) samples of ``DATA/real`` with aligned depth and a camera.json are
built with the default outputs (MJCF, USD, URDF, SDF, glTF, scene.json and the rerun recording:
the largest folder a build writes). Per build: files and megabytes written, seconds of the build,
seconds of :func:`scene_builder.outdir.write_marker` (every file hashed once, as the build's last
step) and of :func:`scene_builder.outdir.check_replaceable` (the folder hashed again and compared,
what a rebuild does before it builds and again before it replaces the folder); each the median
of 5 runs. The control beside them: reading the same files without hashing (``cat`` to nothing,
the page cache warm), which bounds what any content check costs.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

__all__ = ["main", "marker_rows"]

REPEATS = 5


def _median_s(call) -> float:
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _read_all(folder: Path) -> None:
    for p in folder.rglob("*"):
        if p.is_file():
            with open(p, "rb") as f:
                while f.read(1 << 20):
                    pass


def marker_rows(data: Path, samples: int) -> list[dict]:
    from scene_builder.config import BuildConfig, InputSpec
    from scene_builder.outdir import MARKER, check_replaceable, write_marker
    from scene_builder.pipeline import build

    rows = []
    found = sorted(p for p in (Path(data) / "real").iterdir() if (p / "camera.json").is_file() and (p / "depth.png").is_file())
    for src in found[:samples]:
        cam = json.loads((src / "camera.json").read_text())
        inputs = InputSpec(next(src.glob("rgb.*")), src / "depth.png", 0.001, (cam["fx"], cam["fy"], cam["cx"], cam["cy"]))
        with tempfile.TemporaryDirectory() as tmp:
            result = build(inputs, Path(tmp) / "out", BuildConfig())
            out = result.out_dir
            files = [p for p in out.rglob("*") if p.is_file() and p.name != MARKER]
            rows.append(dict(
                sample=src.name, files=len(files), mb=sum(p.stat().st_size for p in files) / 1e6,
                build_s=dict(result.timings_s)["total"],
                read_s=_median_s(lambda: _read_all(out)),
                write_s=_median_s(lambda: write_marker(out, inputs)),
                check_s=_median_s(lambda: check_replaceable(out, inputs)),
            ))
    return rows


def render(rows: list[dict]) -> str:
    lines = [
        "| sample | files | MB | build (s) | read, no hash (s) | marker written: hash (s) | rebuild check: hash again (s) | marker + 2 checks, share of the build |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        share = (r["write_s"] + 2 * r["check_s"]) / r["build_s"]
        lines.append(
            f"| {r['sample']} | {r['files']} | {r['mb']:.1f} | {r['build_s']:.1f} | {r['read_s']:.3f} | {r['write_s']:.3f} | "
            f"{r['check_s']:.3f} | {share * 100:.1f} % |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m scene_builder.bench.outdir", description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[3] / "shared" / "data")
    parser.add_argument("--samples", type=int, default=3)
    args = parser.parse_args(argv)
    print(render(marker_rows(args.data, args.samples)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
