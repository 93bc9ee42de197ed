"""The room's planes on the RGB-D frames of ../shared/data (real/ and multiview/): the plane RANSAC
against open3d's, the floor's height when the floor is not seen, the walls found.

* **RANSAC**: ``perception.room.ransac_plane`` (hand-written, vectorised, least-squares refit)
  against open3d's ``PointCloud.segment_plane`` on the same 10,000-point seeded subsample of each
  frame, at the room's threshold (2.5 cm) and 300 iterations: milliseconds per call, inliers of
  the best plane (median over seeds 0-4), and whether 5 repeated calls with one seed agree.
* **Floor not seen**: each frame's floor is found with everything in view; then everything seen
  below a height h above that floor is dropped, and the camera's height is estimated as the
  room module does without a floor (up taken from the full view, so that only the height is
  compared): the lowest point seen, the prior :data:`perception.room.CAMERA_HEIGHT_PRIOR_M`, and
  the larger of the two (what ``estimate_room`` uses). Also: whether ``estimate_room`` on the cut
  view mistakes a furniture top for the floor.
* **Walls**: walls, partial walls and ceilings found per frame, with the wall candidates' normals
  from open3d (``perception.room.open3d_normals``, what a build uses) or from the depth grid
  (``grid_normals``), the normals' milliseconds and ``estimate_room``'s seconds with each.

The prior camera height is the median of these same frames: its row is in-sample.

Run: ``python -m scene_builder.bench.room_planes [--data ../shared/data]`` (Markdown on stdout).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

CUTS_M = (0.15, 0.5, 0.8)


def frames(data: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, (H, W, 3) camera-frame points, (H, W) valid) of every RGB-D frame whose depth is
    aligned with its photo (intrinsics from camera.json, else a 60 degree field of view)."""
    from PIL import Image

    dirs = sorted((data / "real").glob("*")) + sorted((data / "multiview").glob("*"))
    out = []
    for d in dirs:
        if not (d / "depth.png").exists():
            continue
        depth = np.asarray(Image.open(d / "depth.png")).astype(np.float64) / 1000.0
        h, w = depth.shape
        if (d / "camera.json").exists():
            c = json.loads((d / "camera.json").read_text())
            if (int(c["height"]), int(c["width"])) != (h, w):
                continue
            fx, fy, cx, cy = c["fx"], c["fy"], c["cx"], c["cy"]
        else:
            fx = fy = w / 2.0 / np.tan(np.radians(30.0))
            cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
        v, u = np.mgrid[0:h, 0:w]
        pts = np.stack([(u - cx) / fx * depth, (v - cy) / fy * depth, depth], axis=-1)
        out.append((d.name, pts, (depth > 0) & (depth < 10.0)))
    return out


def ransac_rows(items) -> list[str]:
    import open3d as o3d

    from perception.room import RANSAC_SAMPLES, ransac_plane

    rows = ["| frame | own ms | open3d ms | own inliers | open3d inliers | own repeatable | open3d repeatable |", "|---|---:|---:|---:|---:|---|---|"]
    for name, pts, valid in items:
        p = pts[valid]
        rng = np.random.default_rng(0)
        sample = p[np.sort(rng.choice(len(p), min(RANSAC_SAMPLES, len(p)), replace=False))]
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(sample))
        own, o3 = [], []
        t = time.perf_counter()
        for seed in range(5):
            own.append(int(ransac_plane(sample, 0.025, 300, np.random.default_rng(seed))[2].sum()))
        t_own = (time.perf_counter() - t) / 5
        t = time.perf_counter()
        for seed in range(5):
            o3d.utility.random.seed(seed)
            o3.append(len(pc.segment_plane(0.025, 3, 300)[1]))
        t_o3 = (time.perf_counter() - t) / 5
        rep_own = len({tuple(np.round(ransac_plane(sample, 0.025, 300, np.random.default_rng(0))[0], 9)) for _ in range(5)}) == 1
        reps = set()
        for _ in range(5):
            o3d.utility.random.seed(0)
            reps.add(tuple(np.round(pc.segment_plane(0.025, 3, 300)[0], 9)))
        rows.append(f"| {name} | {1000 * t_own:.0f} | {1000 * t_o3:.0f} | {np.median(own):.0f} | {np.median(o3):.0f} | {'yes' if rep_own else 'no'} | {'yes' if len(reps) == 1 else 'no'} |")
    return rows


def floor_rows(items) -> list[str]:
    from perception.room import CAMERA_HEIGHT_PRIOR_M, estimate_room

    err: dict[float, dict[str, list[float]]] = {c: {"lowest point": [], "prior": [], "larger of both": []} for c in CUTS_M}
    fake: dict[float, list[str]] = {c: [] for c in CUTS_M}
    n = 0
    for name, pts, valid in items:
        full = estimate_room(pts, valid, 0)
        if not full.floor_found:
            continue
        n += 1
        h, up = full.camera_height_m, full.up_cam
        for cut in CUTS_M:
            keep = valid & ((h + pts @ up) > cut)
            low = float(-np.quantile(pts[keep] @ up, 0.005))
            for k, est in (("lowest point", low), ("prior", CAMERA_HEIGHT_PRIOR_M), ("larger of both", max(low, CAMERA_HEIGHT_PRIOR_M))):
                err[cut][k].append(abs(est - h))
            cut_frame = estimate_room(pts, keep, 0)
            if cut_frame.floor_found:
                fake[cut].append(f"{name} ({cut_frame.camera_height_m:.2f} m for {h:.2f} m)")
    rows = [f"Camera height error (m) over the {n} frames with a floor, with nothing seen below h:", "", "| h | lowest point (median / max) | prior (median / max) | larger of both (median / max) | a furniture top taken for the floor |", "|---:|---|---|---|---:|"]
    for cut in CUTS_M:
        cells = [f"{np.median(v):.2f} / {np.max(v):.2f}" for v in err[cut].values()]
        rows.append(f"| {cut:.2f} | " + " | ".join(cells) + f" | {len(fake[cut])} of {n} |")
    rows += ["", "Furniture tops taken for the floor (found height for the true one), h = 0.15 m: " + ("; ".join(fake[CUTS_M[0]]) or "none")]
    return rows


def wall_rows(items) -> list[str]:
    import subprocess
    import sys

    from perception.room import estimate_room, grid_normals, open3d_normals

    # open3d's import, timed in a fresh interpreter (here it may be imported already).
    t = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import open3d"], check=True)
    t_o3d = time.perf_counter() - t
    t = time.perf_counter()
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    t_import = t_o3d - (time.perf_counter() - t)
    rows = [
        f"Importing open3d in a fresh interpreter: {t_import:.2f} s (beyond an empty interpreter's start).",
        "",
        "| frame | walls / partial / ceiling, offsets m (grid normals) | same with open3d normals | normals ms (grid) | normals ms (open3d) | estimate_room s (grid) | estimate_room s (open3d) |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    same = 0
    for name, pts, valid in items:
        t = time.perf_counter()
        grid_normals(pts, valid)
        ms_grid = 1000 * (time.perf_counter() - t)
        t = time.perf_counter()
        open3d_normals(pts[valid])
        ms_o3d = 1000 * (time.perf_counter() - t)
        res = []
        for how in ("grid", "open3d"):
            t = time.perf_counter()
            fr = estimate_room(pts, valid, 0, normals=how)
            dt = time.perf_counter() - t
            kinds = [p.kind for p in fr.planes]
            offs = tuple(sorted(round(float(p.offset_m), 2) for p in fr.planes if p.kind in ("wall", "partial-wall")))
            res.append((f"{kinds.count('wall')} / {kinds.count('partial-wall')} / {'yes' if 'ceiling' in kinds else 'no'}", offs, dt))
        same += res[0][:2] == res[1][:2]
        rows.append(f"| {name} | {res[0][0]} {list(res[0][1])} | {res[1][0]} {list(res[1][1])} | {ms_grid:.0f} | {ms_o3d:.0f} | {res[0][2]:.2f} | {res[1][2]:.2f} |")
    rows += ["", f"Same walls (count and offsets to 1 cm) with either normals: {same} of {len(items)} frames (no wall ground truth here: where they differ, neither is known right)."]
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("--sections", nargs="+", choices=("ransac", "floor", "walls"), default=["ransac", "floor", "walls"])
    args = ap.parse_args(argv)
    items = frames(args.data)
    if "ransac" in args.sections:
        print(f"### Plane RANSAC: hand-written against open3d ({len(items)} frames)\n")
        print("\n".join(ransac_rows(items)) + "\n")
    if "floor" in args.sections:
        print("### The floor's height when the floor is not seen\n")
        print("\n".join(floor_rows(items)) + "\n")
    if "walls" in args.sections:
        print("### Walls found (`perception.room.estimate_room`)\n")
        print("\n".join(wall_rows(items)))


if __name__ == "__main__":
    main()
