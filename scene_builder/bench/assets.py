"""Timing of the shape-prior generator: ``python -m scene_builder.bench.assets``.

Per category of the vocabulary, one synthetic half-observed object of the category's typical
size (``scene_builder.bench.synthetic_boxes``): seconds for the whole object, and for the voxel path
(``object`` label at ``voxel_resolution``) the split into completion, meshing and convex
decomposition. Median of ``--repeats`` runs. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def _time(fn, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def main(argv: list[str] | None = None) -> None:
    from generation.collision import convex_pieces
    from generation.completion import complete_occupancy
    from generation.meshing import mesh_from_occupancy
    from generation.pose import fit_box
    from generation.shape_prior import ShapePriorGenerator, complete_box
    from scene_builder.bench.synthetic_boxes import SyntheticBox, synthetic_perception
    from scene_builder.config import GenerationConfig
    from scene_builder.frames import transform_points
    from scene_builder.vocabulary import CATEGORIES

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--resolution", type=int, default=48)
    args = ap.parse_args(argv)
    config = GenerationConfig(voxel_resolution=args.resolution)
    boxes = [SyntheticBox(c.name, c.typical_size_m, 0.3, (0.0, 0.0, 0.0 if c.on_floor else 0.7)) for c in CATEGORIES]
    perception = synthetic_perception(boxes, noise_m=0.002)
    gen = ShapePriorGenerator()
    gen.generate(perception.objects[0], perception, config)  # warm-up: imports
    print("| category | kind | parts | collision pieces | mass kg | s / object |")
    print("|---|---|---|---|---|---|")
    totals = []
    for obj in perception.objects:
        dt, g = _time(lambda: gen.generate(obj, perception, config), args.repeats)
        totals.append(dt)
        a = g.asset
        pieces = sum(len(p.collision) for p in a.parts)
        print(f"| {a.label} | {a.kind.value} | {len(a.parts)} | {pieces} | {a.mass_kg:.2f} | {dt:.3f} |")
    print(f"\nmedian {statistics.median(totals):.3f} s, max {max(totals):.3f} s per object")

    obj = next(o for o in perception.objects if o.label == "object")
    cam = perception.camera.position_m
    fit = complete_box(fit_box(obj.points_world_m, cam), "object")
    inv = np.linalg.inv(fit.world_from_box)
    pts, cam_a = transform_points(inv, obj.points_world_m), transform_points(inv, cam[None])[0]
    t_c, vg = _time(lambda: complete_occupancy(pts, cam_a, fit.size_m, args.resolution), args.repeats)
    t_m, mesh = _time(lambda: mesh_from_occupancy(vg.occupancy, vg.voxel_size_m, vg.origin_m, config.max_visual_faces), args.repeats)
    # a non-convex shape for the decomposition: the completed box with a notch cut out
    occ = vg.occupancy.copy()
    nx, ny, nz = occ.shape
    occ[nx // 3 :, ny // 3 : 2 * ny // 3, nz // 2 :] = False
    notched = mesh_from_occupancy(occ, vg.voxel_size_m, vg.origin_m, config.max_visual_faces)
    t_d, pieces = _time(lambda: convex_pieces(notched, threshold=config.coacd_threshold, max_pieces=config.max_collision_pieces), args.repeats)
    print(f"\nvoxel path at {args.resolution}^3: completion {t_c:.3f} s, meshing {t_m:.3f} s "
          f"({len(mesh.faces)} faces), CoACD on a notched box {t_d:.3f} s ({len(pieces)} pieces)")


if __name__ == "__main__":
    main()
