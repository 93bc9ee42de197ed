"""Built-in furniture found from its fronts: kitchen runs, fitted wardrobes and counters that no
detector names (COCO has no cabinet) and that depth alone leaves on the background.

1. **Views**: fitted furniture stands against the room's walls, so its faces share their
   directions: for each horizontal axis of the world frame (which follows the walls when they
   were found) whose face the camera sees (within ``MAX_VIEW_DEG`` of head-on), the photo is
   resampled onto a vertical plane with that normal, ``VIEW_DISTANCE_M`` away (a rotation of
   the camera: every vertical plane with that normal is seen head-on in it, at a scale set by
   its distance).
2. **Seeds**: handles (``front_parse._handles``) on the pixels that no object explains.
3. **Fronts**: around each seed, strongest first, a window about ``WINDOW_M`` wide (at the
   depth the photo's depth map gives the seed) is parsed like an object's face
   (``front_parse.parse_face``); the front holding the seed is kept when most of it lies on
   unexplained pixels and it has a front's size at that depth.
4. **Runs**: fronts whose rectangles touch (within ``RUN_GAP_M``) and share rows or columns
   form one run. Its face plane: the depth map's front-most quarter of the run's pixels; when
   that is within ``ON_WALL_M`` of a wall with the same normal (an estimate painted the run onto
   the wall), the run stands in front of that wall by a base cabinet's depth (``BASE_DEPTH_M``)
   when that puts its bottom near the floor, else a wall cabinet's (``WALL_DEPTH_M``). A base
   run's face reaches down to the floor (its plinth).
5. Each run becomes a :class:`~scene_builder.model.PerceivedObject` labelled ``cabinet``,
   named ``built_in_K``, ``built_in=True`` (welded to the room), with its fronts, its mask the
   run's quad in the photo less other objects' pixels, its points the face plane under the mask.

:func:`fronts_and_built_ins` is the perception stage's step: fronts on the objects' own faces
(:func:`perception.fronts.with_fronts`), then the runs found on what they leave unexplained.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from perception.fronts import Face, rectify, with_fronts
from scene_builder.frames import transform_points
from scene_builder.model import BackendUse, Camera, Front, Observation, PerceivedObject, Plane

__all__ = ["BASE_DEPTH_M", "WALL_DEPTH_M", "built_in_runs", "fronts_and_built_ins"]

MAX_VIEW_DEG = 70.0
VIEW_DISTANCE_M = 2.0
VIEW_MAX_PX = 480
WINDOW_M = 1.4
MAX_SEEDS = 8
RUN_GAP_M = 0.12
ON_WALL_M = 0.3
BASE_DEPTH_M = 0.6
WALL_DEPTH_M = 0.35
#: A base run's bottom lies this close to the floor (m) at most; its face reaches down to it.
PLINTH_MAX_M = 0.35
#: A run whose face centre lies this far behind a wall of the room is in the next room (seen
#: through a doorway or a window): not this room's (perception.perceive leaves objects there out
#: alike).
BEHIND_WALL_M = 0.1
#: A built front is at least this share on pixels no object explains.
MIN_FREE_SHARE = 0.7
#: Fronts of built-ins: 12 cm to 1.2 m wide, 10 cm to 2.3 m high.
FRONT_W_M = (0.12, 1.2)
FRONT_H_M = (0.1, 2.3)


def _view_face(camera: Camera, normal: np.ndarray) -> Face | None:
    """The vertical plane with ``normal`` (world, horizontal, toward the camera) VIEW_DISTANCE_M
    in front of the camera, as a :class:`Face` covering what the photo shows of it (rays within
    ``MAX_VIEW_DEG`` of its normal); None when the camera does not see it."""
    k = camera.intrinsics
    c = camera.position_m
    u, v = np.meshgrid(np.linspace(0, k.width_px - 1, 24), np.linspace(0, k.height_px - 1, 24))
    rays_cam = np.stack([(u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, np.ones_like(u)], axis=-1).reshape(-1, 3)
    rays = rays_cam @ camera.world_from_camera[:3, :3].T
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    facing = -(rays @ normal)
    ok = facing > np.cos(np.radians(MAX_VIEW_DEG))
    if ok.mean() < 0.3:
        return None
    t = VIEW_DISTANCE_M / facing[ok]
    pts = c + rays[ok] * t[:, None]
    right = np.cross(np.array([0.0, 0.0, 1.0]), normal)
    a = pts @ right
    z = pts[:, 2]
    a0, a1, z0, z1 = float(a.min()), float(a.max()), float(z.min()), float(z.max())
    plane_point = c - normal * VIEW_DISTANCE_M
    origin = plane_point + right * (a0 - float(plane_point @ right)) + np.array([0.0, 0.0, z0 - plane_point[2]])
    return Face(origin, right, normal, a1 - a0, z1 - z0)


def _depth_at(observation: Observation, px: np.ndarray) -> float:
    """Median depth (m) around pixel ``px`` (u, v); 0 when none."""
    d = observation.depth_m
    h, w = d.shape
    u, v = int(np.clip(px[0], 0, w - 1)), int(np.clip(px[1], 0, h - 1))
    patch = d[max(0, v - 3): v + 4, max(0, u - 3): u + 4]
    patch = patch[patch > 0]
    return float(np.median(patch)) if len(patch) else 0.0


def _project(camera: Camera, world: np.ndarray) -> np.ndarray:
    return camera.intrinsics.project(transform_points(np.linalg.inv(camera.world_from_camera), world))


def _view_fronts(observation: Observation, camera: Camera, view: Face, free: np.ndarray) -> list[tuple[np.ndarray, Front]]:
    """Fronts found around handle seeds in one view: [(corners in view metres (4, 2) a, b; the
    Front with corners on the view plane)]."""
    from skimage.color import rgb2gray

    from perception.front_parse import _handles, parse_face

    img, inside, m = rectify(observation.rgb, camera, view, free)
    vh, vw = img.shape[:2]
    m_v = max(view.width_m, view.height_m) / VIEW_MAX_PX
    if m_v > m:  # rectify caps the image at its own size; re-sample coarser when the view is large
        import cv2

        vw, vh = max(4, int(round(view.width_m / m_v))), max(4, int(round(view.height_m / m_v)))
        img = cv2.resize(img, (vw, vh), interpolation=cv2.INTER_AREA)
        inside = cv2.resize(inside.astype(np.uint8), (vw, vh), interpolation=cv2.INTER_NEAREST) > 0
        m = m_v
    gray = rgb2gray(img).astype(np.float64)
    # (handles as they are, not also opened: on what no object explains, the opened pass's
    # extra blobs seeded "runs" on a dark blue wall with plant holders (coco 446), a furnace
    # (nyuv2_metric3d_00050) and a sign on a dresser (sunrgbd_000017_mmdet3d))
    seeds = [hd for hd in _handles(gray, m, opened=False) if inside[int(hd.centre[1]), int(hd.centre[0])]]
    if seeds:
        seeds = [hd for hd in seeds if hd.score >= 0.2 * seeds[0].score][:MAX_SEEDS]
    found: list[tuple[np.ndarray, Front]] = []
    for hd in seeds:
        hx, hy = hd.centre
        if any(_in_quad(q, np.array([hx * m, (vh - hy) * m])) for q, _ in found):
            continue
        world_h = view.points(np.array(hx * m), np.array((vh - hy) * m))
        px_h = _project(camera, world_h[None])[0]
        depth = _depth_at(observation, px_h)
        if depth <= 0:
            continue
        k = camera.intrinsics
        true_h = transform_points(camera.world_from_camera, np.array([[(px_h[0] - k.cx_px) / k.fx_px * depth, (px_h[1] - k.cy_px) / k.fy_px * depth, depth]]))[0]
        # true sizes at the seed's distance appear 1 / scale times as large in the view
        scale = max(float((camera.position_m - true_h) @ view.normal), 0.3) / VIEW_DISTANCE_M
        half = int(round(0.5 * WINDOW_M / scale / m))
        x0, x1 = max(0, int(hx) - half), min(vw, int(hx) + half)
        y0, y1 = max(0, int(hy) - half), min(vh, int(hy) + half)
        if x1 - x0 < 16 or y1 - y0 < 16:
            continue
        for p in parse_face(img[y0:y1, x0:x1], m * scale, opened=False):
            if p.handle is None or abs(p.handle[0] + x0 - hx) > 2 or abs(p.handle[1] + y0 - hy) > 2:
                continue
            corners = p.corners + np.array([x0, y0])
            bx0, by0 = np.floor(corners.min(axis=0)).astype(int)
            bx1, by1 = np.ceil(corners.max(axis=0)).astype(int)
            if inside[max(0, by0):by1, max(0, bx0):bx1].mean() < MIN_FREE_SHARE:
                continue
            wm, hm = (bx1 - bx0) * m * scale, (by1 - by0) * m * scale
            if not (FRONT_W_M[0] <= wm <= FRONT_W_M[1] and FRONT_H_M[0] <= hm <= FRONT_H_M[1]):
                continue
            ab = np.column_stack([corners[:, 0] * m, (vh - corners[:, 1]) * m])
            world = view.points(ab[:, 0], ab[:, 1])
            front = Front(p.kind, p.hinge, _project(camera, world), world, px_h, float(np.clip(0.5 + 0.5 * p.support, 0, 1)))
            found.append((ab, front))
    return found


def _forward(camera: Camera) -> np.ndarray:
    return camera.world_from_camera[:3, 2]


def _in_quad(ab: np.ndarray, p: np.ndarray) -> bool:
    lo, hi = ab.min(axis=0), ab.max(axis=0)
    return bool(np.all(p >= lo) and np.all(p <= hi))


def _runs(rects: list[np.ndarray], gap: float) -> list[list[int]]:
    """Groups of indices of ``rects`` ((4, 2) corners, view metres) that touch within ``gap``."""
    boxes = [(r[:, 0].min(), r[:, 1].min(), r[:, 0].max(), r[:, 1].max()) for r in rects]
    parent = list(range(len(boxes)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, a in enumerate(boxes):
        for j in range(i + 1, len(boxes)):
            b = boxes[j]
            if a[0] - gap <= b[2] and b[0] - gap <= a[2] and a[1] - gap <= b[3] and b[1] - gap <= a[3]:
                parent[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for i in range(len(boxes)):
        groups.setdefault(find(i), []).append(i)
    return sorted(groups.values(), key=lambda g: min(g))


def built_in_runs(
    objects: tuple[PerceivedObject, ...], observation: Observation, camera: Camera, walls: tuple[Plane, ...] = (), removed: np.ndarray | None = None
) -> tuple[PerceivedObject, ...]:
    """The built-in runs of the photo as new objects (see the module docstring), ids after
    ``objects``'."""
    from skimage.draw import polygon

    h, w = observation.rgb.shape[:2]
    claimed = np.zeros((h, w), dtype=bool)
    for o in objects:
        claimed |= o.mask
    if removed is not None:
        claimed |= removed
    free = ~claimed
    fwd = _forward(camera)
    out: list[PerceivedObject] = []
    next_id = max([o.object_id for o in objects], default=0) + 1
    for axis in (np.array([1.0, 0, 0]), np.array([-1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, -1.0, 0])):
        if -(axis @ fwd) < np.cos(np.radians(MAX_VIEW_DEG)):
            continue
        view = _view_face(camera, axis)
        if view is None:
            continue
        found = _view_fronts(observation, camera, view, free)
        for group in _runs([ab for ab, _ in found], RUN_GAP_M * VIEW_DISTANCE_M / 3.0):
            fronts = [found[i][1] for i in group]
            run = _place_run(fronts, axis, observation, camera, walls)
            if run is None:
                continue
            fronts, world_quad = run
            if any(float(wl.clearance_m(world_quad.mean(axis=0)[None])[0]) < -BEHIND_WALL_M for wl in walls):
                continue  # (nyuv2_metric3d_00100: a "cabinet" 1.1 m behind the wall, welded there, 1.6 m into it)
            quad = _project(camera, world_quad)
            rr, cc = polygon(quad[:, 1], quad[:, 0], (h, w))
            mask = np.zeros((h, w), dtype=bool)
            mask[rr, cc] = True
            mask &= free
            if mask.sum() < 50:
                continue
            free &= ~mask
            points, colors = _face_points(mask, world_quad, camera, observation)
            out.append(PerceivedObject(
                object_id=next_id, name=f"built_in_{len(out) + 1}", label="cabinet",
                label_confidence=float(np.mean([f.score for f in fronts])), mask=mask,
                points_world_m=points, colors_rgb=colors, fronts=tuple(fronts), built_in=True,
            ))
            next_id += 1
    return tuple(out)


def _place_run(fronts: list[Front], normal: np.ndarray, observation: Observation, camera: Camera, walls: tuple[Plane, ...]):
    """(fronts on the run's true face plane, (4, 3) world quad of the run's face) or None (see
    the module docstring, step 4)."""
    c = camera.position_m
    view_off = float(fronts[0].corners_world_m[0] @ normal)  # every view point has this n . x
    # the depth map's points under the fronts' corners and centres
    samples = []
    for f in fronts:
        for p in np.vstack([f.corners_px, f.corners_px.mean(axis=0)[None]]):
            d = _depth_at(observation, p)
            if d > 0:
                k = camera.intrinsics
                pc = np.array([(p[0] - k.cx_px) / k.fx_px * d, (p[1] - k.cy_px) / k.fy_px * d, d])
                samples.append(float(transform_points(camera.world_from_camera, pc[None])[0] @ normal))
    if not samples:
        return None
    off = float(np.percentile(samples, 75))  # front-most quarter (n points toward the camera)
    wall = next((wl for wl in walls if float(wl.normal @ normal) > 0.95), None)

    def scaled(o: float) -> tuple[list[Front], float, float]:
        s = (float(c @ normal) - o) / (float(c @ normal) - view_off)
        fs = []
        for f in fronts:
            wc = c + (f.corners_world_m - c) * s
            fs.append(replace(f, corners_world_m=wc))
        zs = np.array([f.corners_world_m[:, 2] for f in fs])
        return fs, float(zs.min()), float(zs.max())

    if wall is not None and abs(off - (-wall.offset_m)) < ON_WALL_M:
        base = -wall.offset_m + BASE_DEPTH_M
        fs, z0, z1 = scaled(base)
        if not (-0.05 <= z0 <= PLINTH_MAX_M):
            fs, z0, z1 = scaled(-wall.offset_m + WALL_DEPTH_M)
    else:
        fs, z0, z1 = scaled(off)
    if z1 <= 0.05 or float(c @ normal) - float(fs[0].corners_world_m[0] @ normal) <= 0.2:
        return None
    allc = np.vstack([f.corners_world_m for f in fs])
    right = np.cross(np.array([0.0, 0.0, 1.0]), normal)
    a = allc @ right
    a0, a1 = float(a.min()), float(a.max())
    bottom = 0.0 if z0 <= PLINTH_MAX_M else z0
    plane = float(fs[0].corners_world_m[0] @ normal)
    def at(av: float, z: float) -> np.ndarray:
        return normal * plane + right * av + np.array([0.0, 0.0, z])
    quad = np.array([at(a0, bottom), at(a1, bottom), at(a1, z1), at(a0, z1)])
    return fs, quad


def _face_points(mask: np.ndarray, quad: np.ndarray, camera: Camera, observation: Observation) -> tuple[np.ndarray, np.ndarray]:
    """Points of the face plane through ``quad`` under the pixels of ``mask`` (a regular subsample
    of at most 4000) and their colours."""
    vs, us = np.nonzero(mask)
    step = max(1, len(us) // 4000)
    us, vs = us[::step], vs[::step]
    k = camera.intrinsics
    rays = np.column_stack([(us - k.cx_px) / k.fx_px, (vs - k.cy_px) / k.fy_px, np.ones(len(us))]) @ camera.world_from_camera[:3, :3].T
    n = np.cross(quad[1] - quad[0], quad[3] - quad[0])
    n /= np.linalg.norm(n)
    c = camera.position_m
    t = ((quad[0] - c) @ n) / (rays @ n)
    pts = c + rays * t[:, None]
    return pts, observation.rgb[vs, us]


def fronts_and_built_ins(
    objects: tuple[PerceivedObject, ...], observation: Observation, camera: Camera, walls: tuple[Plane, ...] = (), removed: np.ndarray | None = None
) -> tuple[list[PerceivedObject], BackendUse]:
    """The perception stage's step for fronts: ``objects`` with the fronts seen on their faces
    (:func:`perception.fronts.with_fronts`) and the built-in runs found from them (:func:`built_in_runs`), and what was found, as a :class:`BackendUse` for report.json."""
    out = list(with_fronts(objects, observation, camera, walls))
    runs = built_in_runs(tuple(out), observation, camera, walls, removed)
    out += runs
    n_obj = sum(1 for o in out if o.fronts)
    n_fronts = sum(len(o.fronts) for o in out)
    kinds = {k: sum(f.kind == k for o in out for f in o.fronts) for k in ("door", "drawer", "flap")}
    what = ", ".join(f"{v} {k}s" for k, v in kinds.items() if v) or "none"
    use = BackendUse("fronts", "face-cuts", f"{n_fronts} fronts ({what}) on {n_obj} of {len(out)} objects, {len(runs)} of them built-in runs found from their fronts")
    return out, use
