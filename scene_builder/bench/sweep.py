"""No crash on any photo: every image of ``../shared/data`` and perturbed copies of them through
``scene-builder build``; each build must end in a scene or a documented one-line refusal.

Run: ``python -m scene_builder.bench.sweep [--data ../shared/data] [--per-image 6] [--max-width 640]
[--models-dir DIR] [--workers 1] [--json sweep.json] [--resume] [--sample N]``; ``--report
sweep.json`` prints the Markdown of an earlier run.

Inputs (:func:`sources`): every sample folder of ``photos/``, ``photos_gt/``, ``real/`` and
``multiview/`` (``physx_protocol/`` holds no photos). Each is built as it is (the photo plain, and
with its ``depth.png`` when it has one, ``camera.json`` beside it as the CLI finds it), then
``--per-image`` perturbed copies each (:data:`PERTURBATIONS`, assigned round-robin so that every
perturbation is used about equally: crops, rotations by 90 / 180 / 270 degrees and small
angles, a mirror, downscales down to a 64 px thumbnail, JPEG quality 10-30, dark, very dark,
overexposed, grey, low contrast, noise, blur). A copy of a sample with depth aligned to its
photo is built with its depth every other time: geometric perturbations move the depth and
the intrinsics with the photo (nearest neighbour; pixels rotated in from outside are invalid
depth), photometric ones leave them. Copies wider than ``--max-width`` are downscaled first
(the crash classes do not depend on size; a full-size build takes 2-3 times as long).

Every build is a ``scene-builder build ... --viz off --offline -q`` process of its own (a crash
there cannot take the sweep down, and its output is what a user would see), without the USD,
URDF, SDF and glTF exports except every ``--full-exports-every``-th build. Outcomes:

* ``scene``: exit status 0;
* ``refusal``: a documented exit status (``scene_builder.errors``) and the CLI's one-line
  ``error: ...`` message, no traceback;
* ``traceback``: a Python traceback on stderr (the whole traceback is kept), or a death by a
  signal, or a build that ran past ``--timeout-s``.

The JSON (written after every build, so ``--resume`` goes on after an interruption) holds each
build's input, perturbation, exit status, seconds, message or traceback, and the counts.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["PERTURBATIONS", "Item", "Source", "items", "main", "prepare", "run_item", "sources", "summarize"]

DEFAULT_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
SUITES = ("photos", "photos_gt", "real", "multiview")
#: Exit statuses of a documented refusal (``scene_builder.errors``; 2 is argparse's usage error).
DOCUMENTED_EXIT = (1, 2, 3, 4, 5)


@dataclass(frozen=True)
class Source:
    """One sample folder: its photo, its depth map (None without one) and whether that depth has
    the photo's size (only then do perturbed copies carry it)."""

    name: str
    rgb: Path
    depth: Path | None
    depth_aligned: bool


@dataclass(frozen=True)
class Item:
    """One build: a source, the perturbation applied ("none": the file as it is), with its depth
    or plain, and whether every exporter runs."""

    name: str
    source: Source
    perturbation: str
    with_depth: bool
    full_exports: bool


def sources(data: Path) -> list[Source]:
    """The sample folders of ``data`` (sorted by suite, then name)."""
    from PIL import Image

    out = []
    for suite in SUITES:
        root = Path(data) / suite
        if not root.is_dir():
            continue
        for d in sorted(p for p in root.iterdir() if p.is_dir()):
            rgb = next((p for p in (d / "rgb.jpg", d / "rgb.png") if p.is_file()), None)
            if rgb is None:
                continue
            depth = d / "depth.png" if (d / "depth.png").is_file() else None
            aligned = False
            if depth is not None:
                with Image.open(rgb) as a, Image.open(depth) as b:
                    aligned = a.size == b.size
            out.append(Source(f"{suite}/{d.name}", rgb, depth, aligned))
    return out


# ------------------------------------------------------------------------------------------
# Perturbations: (rgb uint8 (H, W, 3), depth uint16 (H, W) or None, K dict or None) -> the same,
# plus how the photo is saved ("png", or "jpg:Q", or "grey").
# ------------------------------------------------------------------------------------------

Image3 = tuple[np.ndarray, "np.ndarray | None", "dict | None"]


def _crop(x0: float, y0: float, x1: float, y1: float) -> Callable[[np.ndarray, np.ndarray | None, dict | None], Image3]:
    def f(rgb, depth, k):
        h, w = rgb.shape[:2]
        a, b, c, d = int(x0 * w), int(y0 * h), max(int(x0 * w) + 1, int(x1 * w)), max(int(y0 * h) + 1, int(y1 * h))
        k2 = None if k is None else {**k, "cx": k["cx"] - a, "cy": k["cy"] - b}
        return rgb[b:d, a:c], None if depth is None else depth[b:d, a:c], k2
    return f


def _rot90(times: int):
    """Rotated counter-clockwise ``times`` x 90 degrees (np.rot90): new (u, v) = (v, W-1-u) per turn."""

    def f(rgb, depth, k):
        for _ in range(times):
            h, w = rgb.shape[:2]
            rgb = np.rot90(rgb)
            depth = None if depth is None else np.rot90(depth)
            if k is not None:
                k = {**k, "fx": k["fy"], "fy": k["fx"], "cx": k["cy"], "cy": w - 1 - k["cx"]}
        return np.ascontiguousarray(rgb), None if depth is None else np.ascontiguousarray(depth), k
    return f


def _rotate(deg: float):
    """Rotated by ``deg`` about the principal point (the image centre without intrinsics): a roll
    of the camera, so the intrinsics stay (for square pixels); the corners rotated in are black
    and their depth invalid."""

    def f(rgb, depth, k):
        from PIL import Image

        h, w = rgb.shape[:2]
        centre = (w / 2.0, h / 2.0) if k is None else (k["cx"] + 0.5, k["cy"] + 0.5)
        out = np.asarray(Image.fromarray(rgb).rotate(deg, resample=Image.BILINEAR, center=centre))
        d = None if depth is None else np.asarray(Image.fromarray(depth.astype(np.int32)).rotate(deg, resample=Image.NEAREST, center=centre)).astype(np.uint16)
        return out, d, k
    return f


def _scale(factor: float | None = None, width: int | None = None):
    def f(rgb, depth, k):
        h, w = rgb.shape[:2]
        s = factor if factor is not None else width / w
        return _resize(rgb, depth, k, s)
    return f


def _resize(rgb, depth, k, s: float) -> Image3:
    from PIL import Image

    h, w = rgb.shape[:2]
    size = (max(1, round(w * s)), max(1, round(h * s)))
    out = np.asarray(Image.fromarray(rgb).resize(size, Image.BILINEAR))
    d = None if depth is None else np.asarray(Image.fromarray(depth.astype(np.int32)).resize(size, Image.NEAREST)).astype(np.uint16)
    k2 = None if k is None else {"fx": k["fx"] * size[0] / w, "fy": k["fy"] * size[1] / h,
                                  "cx": (k["cx"] + 0.5) * size[0] / w - 0.5, "cy": (k["cy"] + 0.5) * size[1] / h - 0.5}
    return out, d, k2


def _tone(fn: Callable[[np.ndarray], np.ndarray]):
    def f(rgb, depth, k):
        return np.clip(fn(rgb.astype(np.float64)), 0, 255).round().astype(np.uint8), depth, k
    return f


def _noise(sigma: float):
    def f(rgb, depth, k):
        rng = np.random.default_rng(0)
        return np.clip(rgb + rng.normal(0.0, sigma, rgb.shape), 0, 255).round().astype(np.uint8), depth, k
    return f


def _blur(radius: float):
    def f(rgb, depth, k):
        from PIL import Image, ImageFilter

        return np.asarray(Image.fromarray(rgb).filter(ImageFilter.GaussianBlur(radius))), depth, k
    return f


def _mirror(rgb, depth, k):
    w = rgb.shape[1]
    k2 = None if k is None else {**k, "cx": w - 1 - k["cx"]}
    return np.ascontiguousarray(rgb[:, ::-1]), None if depth is None else np.ascontiguousarray(depth[:, ::-1]), k2


def _same(rgb, depth, k):
    return rgb, depth, k


#: name -> (transform, how the photo is saved). Geometric ones move depth and intrinsics along.
PERTURBATIONS: dict[str, tuple[Callable, str]] = {
    "crop-centre-60": (_crop(0.2, 0.2, 0.8, 0.8), "png"),
    "crop-top-left-50": (_crop(0.0, 0.0, 0.5, 0.5), "png"),
    "crop-bottom-right-40": (_crop(0.6, 0.6, 1.0, 1.0), "png"),
    "crop-strip-15": (_crop(0.0, 0.45, 1.0, 0.6), "png"),
    "rotate-90": (_rot90(1), "png"),
    "rotate-180": (_rot90(2), "png"),
    "rotate-270": (_rot90(3), "png"),
    "rotate-7": (_rotate(7.0), "png"),
    "rotate-minus-15": (_rotate(-15.0), "png"),
    "mirror": (_mirror, "png"),
    "downscale-50": (_scale(0.5), "png"),
    "downscale-160px": (_scale(width=160), "png"),
    "downscale-64px": (_scale(width=64), "png"),
    "jpeg-10": (_same, "jpg:10"),
    "jpeg-20": (_same, "jpg:20"),
    "jpeg-30": (_same, "jpg:30"),
    "dark": (_tone(lambda x: x * 0.15), "png"),
    "very-dark": (_tone(lambda x: x * 0.03), "png"),
    "overexposed": (_tone(lambda x: x * 3.0), "png"),
    "grey": (_same, "grey"),
    "low-contrast": (_tone(lambda x: 128.0 + (x - 128.0) * 0.15), "png"),
    "noise-25": (_noise(25.0), "png"),
    "blur-4": (_blur(4.0), "png"),
}


def items(srcs: list[Source], per_image: int, full_exports_every: int = 5) -> list[Item]:
    """The builds, in order: each source as it is (plain, and with depth when it has one), then
    ``per_image`` perturbed copies of each (perturbations round-robin over all sources; copies of
    a source with aligned depth carry it every other time)."""
    out: list[Item] = []
    for s in srcs:
        out.append(Item(f"{s.name}", s, "none", False, False))
        if s.depth is not None:
            out.append(Item(f"{s.name}+depth", s, "none", True, False))
    names = list(PERTURBATIONS)
    turn = 0
    for s in srcs:
        for j in range(per_image):
            p = names[turn % len(names)]
            turn += 1
            depth = s.depth_aligned and j % 2 == 0
            out.append(Item(f"{s.name}+{p}" + ("+depth" if depth else ""), s, p, depth, False))
    return [Item(it.name, it.source, it.perturbation, it.with_depth, full_exports_every > 0 and k % full_exports_every == 0)
            for k, it in enumerate(out)]


def _read_camera(folder: Path) -> dict | None:
    path = folder / "camera.json"
    if not path.is_file():
        return None
    cam = json.loads(path.read_text())
    return {key: float(cam[key]) for key in ("fx", "fy", "cx", "cy")}


def prepare(item: Item, folder: Path, max_width: int) -> tuple[Path, Path | None]:
    """The photo (and depth map) ``item`` builds from: the source's own files for "none", else a
    perturbed copy in ``folder`` (with a camera.json beside it when the source has one)."""
    from PIL import Image

    s = item.source
    if item.perturbation == "none":
        return s.rgb, s.depth if item.with_depth else None
    with Image.open(s.rgb) as im:
        rgb = np.asarray(im.convert("RGB"))
    depth = None
    if item.with_depth:
        with Image.open(s.depth) as im:
            depth = np.asarray(im).astype(np.uint16)
    k = _read_camera(s.rgb.parent)
    if rgb.shape[1] > max_width:
        rgb, depth, k = _resize(rgb, depth, k, max_width / rgb.shape[1])
    transform, save = PERTURBATIONS[item.perturbation]
    rgb, depth, k = transform(rgb, depth, k)
    folder.mkdir(parents=True, exist_ok=True)
    if save.startswith("jpg:"):
        path = folder / "rgb.jpg"
        Image.fromarray(rgb).save(path, quality=int(save[4:]))
    elif save == "grey":
        path = folder / "rgb.png"
        Image.fromarray(rgb).convert("L").save(path)
    else:
        path = folder / "rgb.png"
        Image.fromarray(rgb).save(path)
    depth_path = None
    if depth is not None:
        depth_path = folder / "depth.png"
        Image.fromarray(depth).save(depth_path)
    if k is not None:
        h, w = rgb.shape[:2]
        (folder / "camera.json").write_text(json.dumps({**k, "width": w, "height": h}) + "\n")
    return path, depth_path


def _classify(returncode: int, stderr: str) -> tuple[str, str]:
    """(outcome, message or traceback) of one finished build process."""
    if "Traceback (most recent call last)" in stderr:
        return "traceback", stderr[stderr.index("Traceback (most recent call last)"):].strip()
    if returncode == 0:
        return "scene", ""
    if returncode < 0:
        return "traceback", f"killed by signal {-returncode}; stderr tail:\n" + "\n".join(stderr.splitlines()[-20:])
    errors = [line for line in stderr.splitlines() if line.startswith("error: ")]
    if returncode in DOCUMENTED_EXIT and len(errors) == 1:
        return "refusal", errors[0][len("error: "):]
    return "traceback", f"exit status {returncode} without one documented error line; stderr tail:\n" + "\n".join(stderr.splitlines()[-20:])


def run_item(item: Item, work: Path, *, max_width: int = 640, models_dir: Path | None = None, timeout_s: float = 900.0,
             python: str = sys.executable) -> dict:
    """Build ``item`` in its own ``scene-builder build`` process under ``work`` (removed after) and
    return its record: outcome (scene / refusal / traceback), exit status, seconds, the refusal's
    message or the whole traceback, objects built."""
    folder = work / re.sub(r"[^A-Za-z0-9_.+-]", "_", item.name)
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    try:
        image, depth = prepare(item, folder / "in", max_width)
        cmd = [python, "-m", "scene_builder.cli", "build", str(image), "-o", str(folder / "out"), "--viz", "off", "--offline", "-q"]
        if depth is not None:
            cmd += ["--depth", str(depth)]
        if not item.full_exports:
            cmd += ["--no-usd", "--no-urdf", "--no-sdf", "--no-gltf"]
        if models_dir is not None:
            cmd += ["--models-dir", str(models_dir)]
        env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "HF_HUB_OFFLINE": "1"}
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, env=env, check=False,
                                  cwd=Path(__file__).resolve().parents[2])
            outcome, text = _classify(proc.returncode, proc.stderr)
            rc = proc.returncode
        except subprocess.TimeoutExpired:
            outcome, text, rc = "traceback", f"ran past {timeout_s:.0f} s", None
        seconds = time.perf_counter() - t0
        objects = None
        report = folder / "out" / "report.json"
        if outcome == "scene" and report.is_file():
            objects = len(json.loads(report.read_text()).get("objects", []))
        return {"name": item.name, "source": item.source.name, "perturbation": item.perturbation, "with_depth": item.with_depth,
                "full_exports": item.full_exports, "outcome": outcome, "exit_status": rc, "seconds": round(seconds, 1),
                "message": text if outcome == "refusal" else "", "traceback": text if outcome == "traceback" else "",
                "objects": objects, "command": " ".join(cmd[1:])}
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def summarize(records: list[dict]) -> dict:
    """Counts per outcome (all builds, the sources as they are, the perturbed copies), refusals
    grouped by message (numbers and paths blanked), the tracebacks."""
    def count(rs):
        return {o: sum(r["outcome"] == o for r in rs) for o in ("scene", "refusal", "traceback")} | {"builds": len(rs)}

    base = [r for r in records if r["perturbation"] == "none"]
    copies = [r for r in records if r["perturbation"] != "none"]
    kinds: dict[str, list[str]] = {}
    for r in records:
        if r["outcome"] == "refusal":
            key = re.sub(r"/\S+", "PATH", r["message"])
            key = re.sub(r"\d+(\.\d+)?", "N", key)
            kinds.setdefault(key, []).append(r["name"])
    per_perturbation: dict[str, dict] = {}
    for p in sorted({r["perturbation"] for r in records}):
        per_perturbation[p] = count([r for r in records if r["perturbation"] == p])
    return {
        "all": count(records), "as_is": count(base), "perturbed": count(copies),
        "sources": len({r["source"] for r in records}),
        "full_exports": count([r for r in records if r["full_exports"]]),
        "with_depth": count([r for r in records if r["with_depth"]]),
        "per_perturbation": per_perturbation,
        "refusals": [{"message": k, "count": len(v), "builds": sorted(v)} for k, v in sorted(kinds.items(), key=lambda kv: -len(kv[1]))],
        "tracebacks": [{"name": r["name"], "traceback": r["traceback"]} for r in records if r["outcome"] == "traceback"],
        "median_seconds": float(np.median([r["seconds"] for r in records])) if records else None,
    }


def render(doc: dict) -> str:
    """Markdown of a sweep JSON."""
    s = doc["summary"]
    a, b, c = s["all"], s["as_is"], s["perturbed"]
    lines = [
        f"- command: `{doc['command']}`; {doc['date']}; {doc['wall_s'] / 60:.0f} min wall for {a['builds']} builds "
        f"(median {s['median_seconds']:.0f} s per build, machine shared)",
        "",
        "| builds | count | scene | documented refusal | traceback |",
        "|---|---:|---:|---:|---:|",
        f"| every image as it is (plain, and with its depth) | {b['builds']} | {b['scene']} | {b['refusal']} | {b['traceback']} |",
        f"| perturbed copies | {c['builds']} | {c['scene']} | {c['refusal']} | {c['traceback']} |",
        f"| of them with depth | {s['with_depth']['builds']} | {s['with_depth']['scene']} | {s['with_depth']['refusal']} | {s['with_depth']['traceback']} |",
        f"| with every exporter (USD, URDF, SDF, glTF) | {s['full_exports']['builds']} | {s['full_exports']['scene']} | "
        f"{s['full_exports']['refusal']} | {s['full_exports']['traceback']} |",
        f"| all ({s['sources']} images) | {a['builds']} | {a['scene']} | {a['refusal']} | {a['traceback']} |",
        "",
        "Per perturbation (builds: scene / refusal / traceback): "
        + "; ".join(f"{p} {v['builds']}: {v['scene']} / {v['refusal']} / {v['traceback']}" for p, v in s["per_perturbation"].items()) + ".",
        "",
    ]
    if s["refusals"]:
        lines += ["Documented refusals (message with numbers and paths blanked, count, builds):", ""]
        lines += [f"- `{r['message']}`: {r['count']} ({', '.join(r['builds'][:4])}{', ...' if r['count'] > 4 else ''})" for r in s["refusals"]]
        lines.append("")
    if s["tracebacks"]:
        lines += ["Tracebacks:", ""]
        for t in s["tracebacks"]:
            lines += [f"- {t['name']}:", "", "```", t["traceback"][-3000:], "```", ""]
    return "\n".join(lines)


def _write(path: Path, doc: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n")
    tmp.replace(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the shared data folder (photos/, photos_gt/, real/, multiview/)")
    parser.add_argument("--per-image", type=int, default=6, help="perturbed copies per image (default 6)")
    parser.add_argument("--max-width", type=int, default=640, help="copies wider than this are downscaled first (default 640)")
    parser.add_argument("--models-dir", type=Path, help="passed to every build (the offline detectors' folder)")
    parser.add_argument("--workers", type=int, default=1, help="builds at once (default 1)")
    parser.add_argument("--timeout-s", type=float, default=900.0, help="a build running longer counts as a crash (default 900)")
    parser.add_argument("--full-exports-every", type=int, default=5, help="every N-th build runs every exporter (default 5; 0 never)")
    parser.add_argument("--sample", type=int, help="only every k-th build, N builds in all (spread over the list)")
    parser.add_argument("--only", help="only builds whose name matches this regular expression")
    parser.add_argument("--json", type=Path, default=Path("sweep.json"), help="where the results go (default sweep.json)")
    parser.add_argument("--resume", action="store_true", help="keep the builds already in --json and run the others")
    parser.add_argument("--report", type=Path, metavar="JSON", help="print the Markdown of an earlier run and exit")
    args = parser.parse_args(argv)
    if args.report:
        print(render(json.loads(args.report.read_text())))
        return 0
    srcs = sources(args.data)
    if not srcs:
        print(f"error: no sample folders under {args.data}", file=sys.stderr)
        return 3
    todo = items(srcs, args.per_image, args.full_exports_every)
    if args.only:
        todo = [it for it in todo if re.search(args.only, it.name)]
    if args.sample:
        step = max(1, len(todo) // args.sample)
        todo = todo[::step][: args.sample]
    records: list[dict] = []
    if args.resume and args.json.is_file():
        records = json.loads(args.json.read_text())["builds"]
        done = {r["name"] for r in records}
        todo = [it for it in todo if it.name not in done]
    command = "python -m scene_builder.bench.sweep " + " ".join(argv if argv is not None else sys.argv[1:])
    date = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    t0 = time.perf_counter()
    wall0 = 0.0
    if args.resume and args.json.is_file():
        wall0 = float(json.loads(args.json.read_text()).get("wall_s", 0.0))

    def doc() -> dict:
        return {"command": command, "date": date, "wall_s": wall0 + time.perf_counter() - t0, "models_dir": str(args.models_dir or ""),
                "max_width": args.max_width, "per_image": args.per_image, "summary": summarize(records), "builds": records}

    with tempfile.TemporaryDirectory(prefix="sweep-") as tmp, ThreadPoolExecutor(max(1, args.workers)) as pool:
        futures = [pool.submit(run_item, it, Path(tmp), max_width=args.max_width, models_dir=args.models_dir, timeout_s=args.timeout_s)
                   for it in todo]
        for k, fut in enumerate(futures):
            rec = fut.result()
            records.append(rec)
            _write(args.json, doc())
            extra = rec["message"] or (rec["traceback"].splitlines() or [""])[-1]
            print(f"[{k + 1}/{len(todo)}] {rec['name']}: {rec['outcome']} ({rec['seconds']:.0f} s) {extra}", file=sys.stderr, flush=True)
    print(render(doc()))
    return 1 if summarize(records)["all"]["traceback"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
