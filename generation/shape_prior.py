"""The default CPU generator ``"shape-prior"``: one simulation-ready asset per perceived object
from its observed points, a category shape prior and the material table.

Per object: gravity-aligned box from the points (``generation.pose``), completed to the
category's typical depth when the camera saw only a face (never through a wall), then by category

* articulated categories: the articulation template fitted to the box (``articulation``);
* furniture, containers, screens, vessels: a shape prior fitted to the box (``priors``);
* deformables (pillow, cushion, towel, blanket, soft toy): a coarse soft shape with the
  material's soft-body settings;
* everything else (``object``, toilet, lamp, plant): the observed shell extruded away from the
  camera and mirrored (``completion``), marching cubes, CoACD.
"""

from __future__ import annotations

import dataclasses
import functools
import threading
from dataclasses import replace

import numpy as np

from scene_builder.config import GenerationConfig, usable_cores
from scene_builder.frames import cut_by_photo_bottom, pose, transform_points
from generation.visibility import FreeSpace, surface_samples
from scene_builder.model import AssetKind, GeneratedAsset, Inertial, ObjectAsset, PerceivedObject, Perception

__all__ = ["ShapePriorGenerator", "BACKEND_NAME", "complete_box", "depth_to_walls", "fitted_box", "with_structure_mass"]

BACKEND_NAME = "shape-prior"
# a face seen head-on spans less than this fraction of the expected depth: complete the depth
_DEPTH_COMPLETE_FRACTION = 0.6
_MIRROR_X = {"lamp", "plant", "bottle", "bowl", "mug", "soft_toy"}
#: Furniture with a head end (a bed's headboard): mirrored across its width only (mirror_axes).
HEAD_END_LABELS = frozenset({"bed"})
#: A shape prior or template whose surface lies this much in seen free space (a sample of
#: VIOLATION_SAMPLES points) contradicts the observation: the observed shell is used instead.
MAX_FREE_SPACE_SHARE = 0.10
VIOLATION_SAMPLES = 2000
#: A completed voxel this close to another object's observed surface is that object's.
OTHERS_CLEARANCE_M = 0.02
#: Observed surfaces are thinned to this spacing for the ownership distance queries.
OWNERSHIP_SPACING_M = 0.01
#: Visual vertices within this many voxels of the observed depth on the object's own pixels are
#: moved onto it.
SNAP_VOXELS = 1.5
#: How high a category's lowest seen point may be for its box to reach the floor when nothing
#: seen stands under it (others: generation.pose.floor_snap_height_m's 0.3 m); where the camera
#: saw under it, the free space seen carves the box back.
BASE_GAP_M = {"bed": 0.6, "table": 1.0, "desk": 1.0}
#: Large furniture whose front is not always the side the camera sees best (a sofa seen end-on
#: or from behind): its box fit reads the plan by the category's proportions
#: (:func:`generation.pose.fit_box`). Not screens, clocks or bags, whose seen face is their front
#: (a monitor read by its proportions stood its template on a 10 cm foot and toppled).
PLAN_BY_PROPORTIONS = frozenset({"sofa", "bench", "desk", "table", "shelf", "wardrobe", "cabinet", "counter"})
#: Completed voxels keep this far in front of the walls.
WALL_CLEARANCE_M = 0.005
#: A shape prior or template reaching further than this into a wall is not used.
MAX_BEHIND_WALL_M = 0.01


#: Categories whose depth is what was seen (never completed, never turned to a wall: a book's
#: face tilted by estimated depth would become a 15 cm block).
FLAT_LABELS = frozenset({"towel", "blanket", "book", "laptop"})


def depth_to_walls(fit, walls) -> float:
    """How deep (m) ``fit`` can grow away from the camera, its observed front face fixed, before
    its back reaches a wall of ``walls`` (inf when no wall is behind it). A picture or a pillar
    seen against a wall, completed to a table's or a chair's depth, would otherwise reach up to a
    metre into the wall, and the layout would push it (and what it bumps into) that far into the
    room, off its pixels."""
    from generation.pose import travel_to_walls

    rot = fit.world_from_box[:3, :3]
    back = -rot[:, 0]  # the box's +x faces the camera
    d, w, h = (float(v) for v in fit.size_m)
    front = np.array([[d / 2, sy * w / 2, z] for sy in (-1.0, 1.0) for z in (0.0, h)])
    return travel_to_walls(transform_points(fit.world_from_box, front), back, walls)


#: Another object's seen points stop a box's completion (:func:`depth_to_others`) when at least
#: this many of them lie where it would grow ...
MIN_BLOCKING_POINTS = 20
#: ... and that object stands beside this one, not on it: its bottom (2nd height percentile)
#: lies below this share of the box's height (a pillow against a headboard lies on the bed).
BLOCKING_BOTTOM_SHARE = 0.5
#: ... and stands behind what was seen of it: at least this share of its points within the box's
#: width and height lie behind the box's observed back (sunrgbd_imvotenet_000003 without depth:
#: the night stand beside the dresser, both against one wall, in the dresser's width by a few
#: degrees of yaw, cut the dresser to its seen front).
BLOCKING_BEHIND_SHARE = 0.5


def depth_to_others(fit, others_world_m) -> float:
    """How deep (m) ``fit`` can grow away from the camera, its observed front face fixed, before
    its back reaches what another object showed of itself (the frontmost 2 % of that object's
    seen points behind the box's observed back, within its width and height), less
    OTHERS_CLEARANCE_M; inf when nothing stands there. Objects lying on it
    (:data:`BLOCKING_BOTTOM_SHARE`), standing beside what was seen (:data:`BLOCKING_BEHIND_SHARE`)
    and a few stray points (:data:`MIN_BLOCKING_POINTS`) do not stop it. The hidden back of a bed
    completed to a bed's proportions reached 0.9 m past its seen side, over the bench at the foot
    of the bed beyond it (sunrgbd_imvotenet_000005): the camera saw that bench where the
    completion put the bed."""
    box_from_world = np.linalg.inv(fit.world_from_box)
    d, w, h = (float(v) for v in fit.size_m)
    limit = np.inf
    for other in others_world_m:
        if len(other) < MIN_BLOCKING_POINTS:
            continue
        q = transform_points(box_from_world, np.asarray(other, dtype=np.float64))
        if float(np.percentile(q[:, 2], 2)) > BLOCKING_BOTTOM_SHARE * h:
            continue
        band = (np.abs(q[:, 1]) <= w / 2) & (q[:, 2] >= 0.0) & (q[:, 2] <= h)
        behind = band & (q[:, 0] < -d / 2)
        if int(behind.sum()) < MIN_BLOCKING_POINTS or behind.sum() < BLOCKING_BEHIND_SHARE * band.sum():
            continue  # (a neighbour standing beside what was seen, in the box's width by a tilt)
        front_x = float(np.percentile(q[behind, 0], 98))
        limit = min(limit, d / 2 - front_x - OTHERS_CLEARANCE_M)
    return limit


def complete_box(fit, label: str, walls=(), others_world_m=()):
    """The box grown away from the camera to the depth expected from the category's typical
    proportions, scaled by the measured width and height (geometric mean of both ratios),
    when the observed depth is less than 60 % of it; never past a wall of ``walls`` (the room's
    walls, :func:`depth_to_walls`) nor into what another object of ``others_world_m`` ((N_k, 3)
    seen points each) showed of itself (:func:`depth_to_others`; not for :data:`HOLDS_INSIDE`
    categories, whose contents stand inside them). Flat categories (towel, blanket) keep the
    observed depth."""
    from generation.pose import extend_depth
    from scene_builder.vocabulary import category

    if label in FLAT_LABELS:
        return fit
    td, tw, th = category(label).typical_size_m
    d, w, h = (float(v) for v in fit.size_m)
    if label == "object":
        expected = float(np.sqrt(w * h))  # unknown: as deep as the face is on average wide/high
    else:
        expected = td * float(np.sqrt((w / tw) * (h / th)))
    if d < _DEPTH_COMPLETE_FRACTION * expected:
        # (a shelf's completion holds what stands inside it: promptda_arkit's books, seen in the
        # bookcase's cubbies behind its front, stopped it at its front frame)
        others = depth_to_others(fit, others_world_m) if label not in HOLDS_INSIDE else np.inf
        return extend_depth(fit, min(expected, depth_to_walls(fit, walls), others))
    return fit


def fitted_box(points_world_m: np.ndarray, camera_position_m: np.ndarray, label: str, walls=(), *, floor_snap_m: float,
               typical_size_m: tuple[float, float, float] | None = None, face_normal: np.ndarray | None = None, others_world_m=()):
    """An object's box: :func:`generation.pose.fit_box` (a face seen near one of ``walls`` turned
    parallel to it, except for :data:`FLAT_LABELS`, whose seen rectangle is what they are),
    completed by :func:`complete_box` (never past ``walls`` nor into the seen points of the other
    objects, ``others_world_m``). ``face_normal``: see ``fit_box``."""
    from generation.pose import fit_box

    fit = fit_box(points_world_m, camera_position_m, floor_snap_m=floor_snap_m, typical_size_m=typical_size_m,
                  walls=() if label in FLAT_LABELS else walls, face_normal=face_normal)
    return complete_box(fit, label, walls, others_world_m)


#: Another object with this share of its points inside a shelf's box is held by the shelf.
HELD_SHARE = 0.8


def _held(others_world_m, box_from_world: np.ndarray, size_m) -> list[tuple[float, float, float, float, float]]:
    """(bottom, top, y from, y to, x front) in the box frame (2nd / 98th percentiles) of each object of
    ``others_world_m`` (point arrays) whose points lie in the box of ``size_m`` (a shelf's
    contents)."""
    d, w, h = (float(v) for v in size_m)
    held = []
    for o in others_world_m:
        q = transform_points(box_from_world, o)
        inside = (np.abs(q[:, 0]) <= d / 2) & (np.abs(q[:, 1]) <= w / 2) & (q[:, 2] >= 0.0) & (q[:, 2] <= h)
        if np.mean(inside) >= HELD_SHARE:
            z0, z1 = np.percentile(q[:, 2], [2, 98])
            y0, y1 = np.percentile(q[:, 1], [2, 98])
            held.append((float(z0), float(z1), float(y0), float(y1), float(np.percentile(q[:, 0], 98))))
    return held


@functools.lru_cache(maxsize=64)
def _ownership(obj: PerceivedObject) -> tuple[np.ndarray, float, tuple]:
    """(points thinned to OWNERSHIP_SPACING_M, 2nd height percentile, :func:`_column`) of a
    perceived object. Every object's completion looks at every other object: cached per object
    (a frozen dataclass compared by identity), they are computed once per build, not n^2 times."""
    p = obj.points_world_m
    thin = _thin(p, OWNERSHIP_SPACING_M)
    thin.flags.writeable = False
    return thin, float(np.percentile(p[:, 2], 2)), _column(p)


#: Another object rests on this one when its bottom (2nd height percentile) lies within this of
#: this one's top (98th) and RESTING_SHARE of its points lie over this one's box in plan.
RESTING_BAND_M = 0.05
RESTING_SHARE = 0.5


def _resting_on(obj: PerceivedObject, others: list[PerceivedObject], world_from_box: np.ndarray, size_m) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) box-frame points of the objects of ``others`` resting on ``obj`` (see
    :data:`RESTING_BAND_M`) and (M,) the box-frame bottom of the object each belongs to. (The
    heights are :func:`_ownership`'s, cached per object.)"""
    top = _ownership(obj)[2][2]
    box_from_world = np.linalg.inv(world_from_box)
    half = np.asarray(size_m, dtype=np.float64)[:2] / 2.0
    pts, bottoms = [np.zeros((0, 3))], [np.zeros(0)]
    for o in others:
        bottom = _ownership(o)[1]
        if abs(bottom - top) > RESTING_BAND_M:
            continue
        local = transform_points(box_from_world, o.points_world_m)
        if np.mean(np.all(np.abs(local[:, :2]) <= half, axis=1)) < RESTING_SHARE:
            continue
        pts.append(local)
        bottoms.append(np.full(len(local), bottom - float(world_from_box[2, 3])))
    return np.concatenate(pts), np.concatenate(bottoms)


def _column(points_world_m: np.ndarray):
    """(plan outline as a shapely Polygon, bottom, top) of another object's observed points: the
    convex hull of their plan positions, shrunk by 2 cm, and their 2nd / 98th height
    percentiles."""
    import shapely

    p = np.asarray(points_world_m, dtype=np.float64)
    lo, hi = np.percentile(p[:, 2], [2, 98])
    hull = shapely.MultiPoint(_thin(p, 0.02)[:, :2]).convex_hull.buffer(-0.02)
    return hull, float(lo), float(hi)


#: Categories that hold things inside their outline (between their boards), not only on top.
HOLDS_INSIDE = frozenset({"shelf"})
#: An object is inside another's column (held in it, not lying on its top) when its median height
#: is this far below that column's top and most of its points lie within its plan outline.
INSIDE_BELOW_TOP_M = 0.05


def _inside_column(points_world_m: np.ndarray, column) -> bool:
    """Whether an object's observed points stand inside ``column`` (see :func:`_column`): half
    or more of them within its plan outline and their median height ``INSIDE_BELOW_TOP_M`` or
    more below its top (a book in a bookcase; a mat lying on a bed is at the bed's top)."""
    import shapely

    outline, _, z_hi = column
    p = np.asarray(points_world_m, dtype=np.float64)
    if outline.is_empty or float(np.median(p[:, 2])) > z_hi - INSIDE_BELOW_TOP_M:
        return False
    return float(np.mean(shapely.contains_xy(outline, p[:, 0], p[:, 1]))) >= 0.5


def completion_blockers(obj: PerceivedObject, others: list[PerceivedObject]) -> list[PerceivedObject]:
    """The objects of ``others`` whose seen points stop ``obj``'s box completion
    (:func:`depth_to_others`) and whose columns carve its voxels: every one but a shelf that holds
    ``obj`` inside its column (a book row in a bookcase's cubby stopped at the back panel's
    blurred depth was a 1 cm sliver that toppled, promptda_arkit; carved to the column, a sliver
    of its front face)."""
    return [o for o in others if not (o.label in HOLDS_INSIDE and _inside_column(obj.points_world_m, _ownership(o)[2]))]


def _thin(points_m: np.ndarray, spacing_m: float) -> np.ndarray:
    """One point per occupied ``spacing_m`` grid cell of (N, 3) points (the first, in input
    order: deterministic)."""
    k = np.floor(np.asarray(points_m) / spacing_m).astype(np.int64) + (1 << 20)
    keys = (k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2]  # 21 bits per axis: +-10 km at 1 cm
    _, first = np.unique(keys, return_index=True)
    return np.asarray(points_m)[np.sort(first)]


def with_structure_mass(asset: ObjectAsset, structure_mass_kg: float) -> ObjectAsset:
    """``asset`` (an observed shape completed where its category's prior did not fit) with the
    mass of the category's structure at the same size.

    A completed shape fills the hidden space inside its observed outline: a chair seen from the
    front becomes a block from the seat to the floor, a shelf a solid box, several times the
    material of the real object, whose legs or boards leave that space empty. The prior fitted to
    the same box says how much material the structure has; the completed solid gets the effective
    density (material density x prior mass / solid mass) that gives it that mass. Density scales
    mass and inertia alike and leaves the centre of mass where it is, so the inertials are scaled
    rather than integrated again. ``structure_mass_kg`` > 0 and below the asset's mass.
    """
    ratio = structure_mass_kg / asset.mass_kg
    if not 0.0 < ratio < 1.0:
        raise ValueError(f"with_structure_mass: structure mass {structure_mass_kg} kg is not below {asset.mass_kg} kg")
    parts = []
    for part in asset.parts:
        m = part.material
        material = replace(m, density_kg_m3=m.density_kg_m3 * ratio,
                           source=f"{m.source}; effective density: {ratio:.2f} of the solid, the mass of the {asset.label}'s structure".lstrip("; "))
        inertial = Inertial(part.inertial.mass_kg * ratio, part.inertial.com_m, part.inertial.inertia_kg_m2 * ratio)
        parts.append(replace(part, material=material, inertial=inertial))
    description = f"{asset.description}; effective density {ratio:.2f} x {asset.parts[0].material.name} (mass of the category's structure)"
    return replace(asset, parts=tuple(parts), description=description)


#: A front layout's top comes down by up to this much (5 mm steps) onto the silhouette seen.
MAX_TOP_DROP_M = 0.08
TOP_DROP_STEP_M = 0.005


def top_within_silhouette(space, world_from_box: np.ndarray, size_m: np.ndarray) -> float:
    """The height (m) for the top of a box (``world_from_box``: its bottom centre, ``size_m``
    depth x width x height) at which at most MAX_FREE_SPACE_SHARE of its top face lies in seen
    free space or off the object's silhouette (``space``: a ``FreeSpace`` with its mask), lowered
    from ``size_m[2]`` by at most MAX_TOP_DROP_M; ``size_m[2]`` when no such height is found.

    The measured extents read the top at the 98th percentile of the points: a few centimetres
    above the top for a night stand with a lamp's base on it, or seen from above at a grazing
    angle; the front layout's top face then showed over the silhouette and failed the
    free-space test (sunrgbd_imvotenet_000004: 13 % of its surface, 7 % without its top 1 cm)."""
    g = np.linspace(-0.45, 0.45, 12)
    gx, gy = np.meshgrid(g * size_m[0], g * size_m[1])
    for drop in np.arange(0.0, MAX_TOP_DROP_M + 1e-9, TOP_DROP_STEP_M):
        top = float(size_m[2]) - drop
        pts = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, top)], axis=1)
        if float(np.mean(space.free(transform_points(world_from_box, pts)))) <= MAX_FREE_SPACE_SHARE:
            return top
    return float(size_m[2])


def _box_bounds(size_m) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners in its own frame of a box of ``size_m`` (depth x width x height) whose
    origin is its bottom centre."""
    size = np.asarray(size_m, dtype=np.float64)
    return np.array([-size[0] / 2, -size[1] / 2, 0.0]), np.array([size[0] / 2, size[1] / 2, size[2]])


def _box_from_bounds(world_from_box: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(world_from_box, size_m) of the box spanning ``lo``..``hi`` in the frame of
    ``world_from_box`` (its bottom at lo[2] = 0), its origin again at its bottom centre."""
    return world_from_box @ pose(np.eye(3), [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.0]), hi - lo


#: A front layout that fills seen free space has its sides, top and front moved inward by up to
#: this share of each extent (TRIM_STEP_M at a time) before it is given up.
MAX_TRIM_SHARE = 0.3
TRIM_STEP_M = 0.01
#: ... and never past this percentile of the object's own points (from each side).
TRIM_KEEP_PCT = 5.0
#: Sample grid per face (cells along each of its two directions) for the trim.
TRIM_GRID = 10


def box_within_free_space(space, world_from_box: np.ndarray, size_m: np.ndarray, points_box_m: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(world_from_box, size_m) of the box (bottom centre, depth x width x height) with its faces
    moved inward until none has more than MAX_FREE_SPACE_SHARE of its surface in seen free space
    (``space.violation``: the test the layout failed, not the silhouette's): the worst face first,
    TRIM_STEP_M at a time, each by at most MAX_TRIM_SHARE of its extent and never past the
    TRIM_KEEP_PCT-th percentile of the object's own points ``points_box_m`` (N, 3, box frame) along
    it (what the camera saw of the object stays inside). The two sides, the top and the front
    move; the back (hidden) and the bottom (on what holds it) stay.

    A box measured on a mask that took in a sliver of the neighbour (sunrgbd_imvotenet_000003's
    dresser, its mask 15 cm over the night stand beside it) showed its side over what was seen
    there, and the whole front layout was given up for the observed shell."""
    size = np.asarray(size_m, dtype=np.float64)
    lo, hi = _box_bounds(size)
    limit_lo, limit_hi = lo + MAX_TRIM_SHARE * size, hi - MAX_TRIM_SHARE * size
    if points_box_m is not None and len(points_box_m):
        limit_lo = np.minimum(limit_lo, np.percentile(points_box_m, TRIM_KEEP_PCT, axis=0))
        limit_hi = np.maximum(limit_hi, np.percentile(points_box_m, 100.0 - TRIM_KEEP_PCT, axis=0))
    g = (np.arange(TRIM_GRID) + 0.5) / TRIM_GRID
    faces = [(1, False), (1, True), (2, True), (0, True)]  # (axis, upper bound) of the faces that move
    stuck = set()
    for _ in range(int(np.ceil(MAX_TRIM_SHARE * size.max() / TRIM_STEP_M)) * len(faces)):
        shares = []
        for i, (axis, upper) in enumerate(faces):
            if i in stuck:
                shares.append(-1.0)
                continue
            a, b = [k for k in range(3) if k != axis]
            ga, gb = np.meshgrid(lo[a] + g * (hi[a] - lo[a]), lo[b] + g * (hi[b] - lo[b]))
            pts = np.empty((ga.size, 3))
            pts[:, axis] = hi[axis] if upper else lo[axis]
            pts[:, a], pts[:, b] = ga.ravel(), gb.ravel()
            shares.append(space.violation(transform_points(world_from_box, pts)))
        i = int(np.argmax(shares))
        if shares[i] <= MAX_FREE_SPACE_SHARE:
            break
        axis, upper = faces[i]
        if upper and hi[axis] - TRIM_STEP_M >= limit_hi[axis]:
            hi[axis] -= TRIM_STEP_M
        elif not upper and lo[axis] + TRIM_STEP_M <= limit_lo[axis]:
            lo[axis] += TRIM_STEP_M
        else:
            stuck.add(i)
    return _box_from_bounds(world_from_box, lo, hi)


#: A wall stands against a side of a box when its normal is within this angle of the side's
#: inward direction.
WALL_SIDE_DEG = 30.0


def box_clear_of_walls(world_from_box: np.ndarray, size_m: np.ndarray, walls) -> tuple[np.ndarray, np.ndarray]:
    """(world_from_box, size_m) of the box (bottom centre, depth x width x height) with each of its
    four vertical sides that reaches behind a wall standing against it (:data:`WALL_SIDE_DEG`)
    moved back in front of that wall (WALL_CLEARANCE_M), by at most MAX_TRIM_SHARE of the extent
    (else that side stays and the layout fails as before). Unlike :func:`box_within_free_space`
    this may cut into the object's own points: estimated depth bleeds a mask's edge onto the wall
    and beyond it, and nothing of the room's furniture stands inside a wall (coco 164's cabinet:
    its points reach 10 cm past the side wall it stands against, and its front layout was given
    up for the observed shell)."""
    size = np.asarray(size_m, dtype=np.float64)
    lo, hi = _box_bounds(size)
    rot = world_from_box[:3, :3]
    cos_side = float(np.cos(np.radians(WALL_SIDE_DEG)))
    for axis in (0, 1):
        for upper in (False, True):
            outward = rot[:, axis] * (1.0 if upper else -1.0)
            a = 1 - axis
            corners = np.array([[0.0, 0.0, z] for z in (lo[2], hi[2])] * 2)
            corners[:, axis] = hi[axis] if upper else lo[axis]
            corners[:, a] = [lo[a], lo[a], hi[a], hi[a]]
            world = transform_points(world_from_box, corners)
            for wall in walls:
                if float(np.asarray(wall.normal) @ outward) > -cos_side:
                    continue
                cut = WALL_CLEARANCE_M - float(np.min(wall.clearance_m(world)))
                if 0.0 < cut <= MAX_TRIM_SHARE * size[axis]:
                    if upper:
                        hi[axis] -= cut
                    else:
                        lo[axis] += cut
    return _box_from_bounds(world_from_box, lo, hi)


def fronts_normal(fronts) -> np.ndarray | None:
    """(3,) the horizontal unit normal (world) of the face ``fronts`` were seen on (facing the
    camera), or None when there are none."""
    n = np.zeros(3)
    for f in fronts:
        c = f.corners_world_m  # bl, br, tr, tl
        n += np.cross(c[1] - c[0], c[3] - c[0])
    n[2] = 0.0
    length = float(np.linalg.norm(n))
    return n / length if length > 0 else None


#: A box's front stands at most this far (m) in front of the face its fronts were seen on.
FRONT_PAST_FACE_M = 0.01


def front_on_face(fit, fronts):
    """``fit`` (a ``BoxFit`` whose +X faces the face ``fronts`` were seen on) with its front
    brought back onto that face (the mean of their corners along +X) where it stood more than
    FRONT_PAST_FACE_M in front of it; its back stays. The box's extents reach the 99th percentile
    of the points plus a margin: on a structured-light sensor's depth 4 m away (2 cm noise,
    handles standing out) that put a dresser's front 11 cm before the drawers, in what the camera
    saw through, and its front layout was given up."""
    box_from_world = np.linalg.inv(fit.world_from_box)
    face_x = float(np.mean([transform_points(box_from_world, f.corners_world_m)[:, 0] for f in fronts]))
    lo, hi = _box_bounds(fit.size_m)
    if hi[0] <= face_x + FRONT_PAST_FACE_M or face_x <= lo[0] + 0.05:
        return fit
    hi[0] = face_x
    world_from_box, size = _box_from_bounds(fit.world_from_box, lo, hi)
    return dataclasses.replace(fit, world_from_box=world_from_box, size_m=size)


def face_fitted_box(obj: PerceivedObject, space, camera_position_m: np.ndarray, walls, floor_snap_m: float, others_world_m=(), camera=None,
                    beside_world_m=()):
    """(BoxFit, size) of an object with fronts whose first front layout failed the free-space
    test: the box with the axes of the face its fronts were seen on (``fit_box``'s
    ``face_normal``), its front on that face (:func:`front_on_face`), grown to a cabinet's least
    size, its top on the silhouette (:func:`top_within_silhouette`), then trimmed to the seen
    free space (:func:`box_within_free_space`). On sunrgbd_imvotenet_000003 the night stand's and
    the dresser's layouts failed (24-25 % of their surface in free space): boxes 8 degrees off
    their faces, 10 cm in front of them (the 99th percentile of depth 4 m away), over a sliver of
    the neighbour their masks took in. ``camera`` (a :class:`~scene_builder.model.Camera`), when
    given: widened past a side edge of the photo that cut it (:mod:`generation.out_of_view`, short
    of the seen points of ``beside_world_m``), as :func:`observed_box` widens the first box."""
    from generation.out_of_view import width_out_of_view
    from scene_builder.vocabulary import category

    fit = fitted_box(obj.points_world_m, camera_position_m, obj.label, walls, floor_snap_m=floor_snap_m, face_normal=fronts_normal(obj.fronts),
                     others_world_m=others_world_m)
    fit = front_on_face(fit, obj.fronts)
    if camera is not None:
        fit = width_out_of_view(fit, obj.label, obj.mask, camera, walls, beside_world_m)[0]
    size = np.maximum(fit.size_m, 0.3 * np.asarray(category("cabinet").typical_size_m))
    size[2] = top_within_silhouette(space, fit.world_from_box, size)
    world_from_box, size = box_clear_of_walls(fit.world_from_box, size, walls)
    pts = transform_points(np.linalg.inv(world_from_box), obj.points_world_m)
    world_from_box, size = box_within_free_space(space, world_from_box, size, pts)
    return dataclasses.replace(fit, world_from_box=world_from_box, size_m=size.copy()), size


def _median_rgba(colors_rgb: np.ndarray) -> tuple[float, float, float, float]:
    c = np.median(np.asarray(colors_rgb, dtype=np.float64), axis=0) / 255.0
    return (float(c[0]), float(c[1]), float(c[2]), 1.0)


def mirror_axes(label: str, points_box_m: np.ndarray) -> tuple[bool, bool]:
    """(mirror_x, mirror_y): across which of its box's vertical mid-planes an object's observed
    shell is mirrored to complete it (``generation.completion.complete_occupancy``), its points
    ``points_box_m`` (N, 3) in its box frame (x toward the camera, y across). Left to right
    always; front to back too for the round things of ``_MIRROR_X``. A bed
    (:data:`HEAD_END_LABELS`) only across its width, the shorter of its seen plan extents:
    mirrored end to end, a bed seen from its side grew a second headboard at its foot
    (sunrgbd_imvotenet_000005)."""
    if label in HEAD_END_LABELS:
        along_y = bool(np.ptp(points_box_m[:, 1]) > np.ptp(points_box_m[:, 0]))
        return along_y, not along_y
    return label in _MIRROR_X, True


@dataclasses.dataclass(frozen=True, eq=False)
class ObservedBox:
    """An object's box as the photo showed it (:func:`observed_box`): ``fit`` the completed,
    gravity-aligned box (``generation.pose.fit_box``'s result after :func:`complete_box`),
    ``floor_snap_m`` the largest gap under its lowest seen point that its box closes down to the
    floor (inf: cut by the photo's bottom edge, down to the floor whatever the gap),
    ``cut_to_floor`` whether it was so cut, ``blockers`` the other
    objects whose seen points stopped its completion (:func:`completion_blockers`),
    ``out_of_view_m`` how far it was widened past the photo's ``cut_side`` edge
    (:mod:`generation.out_of_view`; 0 and "" when not)."""

    fit: object
    floor_snap_m: float
    cut_to_floor: bool
    blockers: tuple
    out_of_view_m: float = 0.0
    cut_side: str = ""


def observed_box(obj: PerceivedObject, perception: Perception) -> ObservedBox:
    """The box of ``obj`` every generator poses its asset on: snapped to the floor from up to its
    category's base gap (:data:`BASE_GAP_M`, else 0.3 m), down to the floor when the photo's
    bottom edge cut floor furniture over a seen floor, its plan read by the category's
    proportions for :data:`PLAN_BY_PROPORTIONS` without fronts, completed no farther than the
    walls and what its :func:`completion_blockers` showed of themselves."""
    from generation.out_of_view import width_out_of_view
    from generation.pose import floor_snap_height_m
    from scene_builder.vocabulary import category

    label = obj.label
    cat = category(label)
    other_objects = [o for o in perception.objects if o.name != obj.name]
    others = [o.points_world_m for o in other_objects]
    # A bed's base reaches the floor: seen from its mattress down to 0.47 m only (a bench at
    # its foot hides the rest, sunrgbd_imvotenet_000004), it is no mattress on 0.47 m legs.
    snap_m = floor_snap_height_m(obj.points_world_m, others, max_gap_m=BASE_GAP_M.get(label, 0.3))
    floor_seen = any(b.task == "floor" and b.backend == "floor-plane" for b in perception.backends)
    if floor_seen and cat.on_floor and cut_by_photo_bottom(obj.mask, perception.observation.valid_depth):
        # The photo's bottom edge cut it (a sideboard's top and upper front in the photo's
        # corner): what is below it was never seen, so floor furniture reaches the floor,
        # unless another object's top lies under it (the snap height is then the default).
        # (Not to a floor put under what was seen: a close-up of a cabinet shows no floor.)
        if floor_snap_height_m(obj.points_world_m, others, max_gap_m=np.inf) > snap_m:
            snap_m = np.inf
    # The plan orientation of large furniture follows the category's proportions (a sofa
    # seen end-on), unless fronts seen on a face say which face is the front.
    typical = cat.typical_size_m if label in PLAN_BY_PROPORTIONS and not obj.fronts else None
    blocking = tuple(completion_blockers(obj, other_objects))
    fit = fitted_box(obj.points_world_m, perception.camera.position_m, label, perception.room.walls, floor_snap_m=snap_m,
                     typical_size_m=typical, others_world_m=[o.points_world_m for o in blocking])
    # furniture a side edge of the photo cut continues past it (its seen end stays)
    fit, grown, side = width_out_of_view(fit, label, obj.mask, perception.camera, perception.room.walls, others)
    return ObservedBox(fit, float(snap_m), bool(np.isinf(snap_m)), blocking, grown, side)


class ShapePriorGenerator:
    """Category shape priors + observed-shell completion on the CPU (always available)."""

    name = BACKEND_NAME

    def generate(self, obj: PerceivedObject, perception: Perception, config: GenerationConfig, seed: int = 0) -> GeneratedAsset:
        """One :class:`GeneratedAsset` for ``obj`` (asset name = ``obj.name``)."""
        from generation.articulation import ARTICULATED_LABELS, articulated_parts
        from generation.assembly import ConvexSolids, PartSpec, assemble_asset_with_offset, box_solid
        from generation.completion import complete_occupancy, superellipsoid_occupancy
        from generation.materials import category_material, deformable_settings
        from generation.physics import too_small
        from scipy.spatial import cKDTree

        from generation.priors import PRIOR_LABELS, prior_parts, shelf_boards, table_legs
        from generation.proportions import TABLE_LABELS, fit_leg_inset, seen_proportions
        from scene_builder.vocabulary import category

        label = obj.label
        cat = category(label)
        cam_world = perception.camera.position_m
        other_objects = [o for o in perception.objects if o.name != obj.name]
        others = [o.points_world_m for o in other_objects]
        seen_box = observed_box(obj, perception)
        fit, snap_m, cut_to_floor, blocking = seen_box.fit, seen_box.floor_snap_m, seen_box.cut_to_floor, seen_box.blockers
        blockers = [o.points_world_m for o in blocking]
        box_from_world = np.linalg.inv(fit.world_from_box)
        pts = transform_points(box_from_world, obj.points_world_m)
        cam = transform_points(box_from_world, cam_world[None])[0]
        size = fit.size_m.copy()
        rgba = _median_rgba(obj.colors_rgb)
        cm = category_material(label)
        soft = deformable_settings(label)
        kind = None
        seen_w = size[1] - seen_box.out_of_view_m  # (the width the photo showed)
        description = f"{label} fitted to measured extents {size[0]:.2f} x {seen_w:.2f} x {size[2]:.2f} m (depth x width x height)"
        if cut_to_floor:
            description += ", down to the floor below the photo's bottom edge, which cut it"
        if seen_box.out_of_view_m > 0:
            description += f", continued {seen_box.out_of_view_m:.2f} m out of view past the photo's {seen_box.cut_side} edge, which cut it"
        cfg = config

        rects = []
        measured = None  # a bed's proportions as seen (generation.proportions)
        space = FreeSpace(perception.observation, perception.camera, own_mask=obj.mask)
        if obj.fronts:  # doors and drawers where the photo showed them (generation.front_parts)
            from generation.front_parts import front_parts, seen_rectangles

            size = np.maximum(size, 0.3 * np.asarray(category("cabinet").typical_size_m))
            size[2] = top_within_silhouette(space, fit.world_from_box, size)
            # Clear of the walls behind and beside it (estimated depth bleeds a mask past them:
            # sunrgbd_total3d_demo_5's night stand reached 4 cm into the wall behind it).
            world_from_box, size = box_clear_of_walls(fit.world_from_box, size, perception.room.walls)
            if not np.array_equal(world_from_box, fit.world_from_box):
                fit = dataclasses.replace(fit, world_from_box=world_from_box, size_m=size.copy())
                box_from_world = np.linalg.inv(world_from_box)
                pts = transform_points(box_from_world, obj.points_world_m)
                cam = transform_points(box_from_world, cam_world[None])[0]
            rects = seen_rectangles(obj.fronts, fit.world_from_box, size, perception.room.walls)
        if rects:
            specs = front_parts(label, size, rects, rgba)
            description += f"; {len(rects)} fronts seen in the photo"
        elif label in ARTICULATED_LABELS:
            size = np.maximum(size, 0.3 * np.asarray(cat.typical_size_m))  # templates need room for panels
            specs = articulated_parts(label, size, rgba)
            description += "; articulation template"
        elif label in PRIOR_LABELS:
            # panels need room: a sliver of points (a shelf seen edge-on) would leave an empty box
            size = np.maximum(size, 0.15 * np.asarray(cat.typical_size_m))
            boards = None
            if label == "shelf":
                held = _held(others, box_from_world, size)
                boards = shelf_boards(held, size, pts) if held else None
            measured = seen_proportions(label, pts, size)
            if measured is not None and label in TABLE_LABELS:
                measured = fit_leg_inset(measured, space, fit.world_from_box, size, table_legs, seed)
            specs = prior_parts(label, size, cm.material, cm.shell_thickness_m, rgba, config.max_collision_pieces, boards, measured)
            description += "; shape prior" if boards is None else f"; shape prior, {len(boards)} boards under what it holds"
            if measured is not None:
                description += f", {measured.describe(label)} as seen"
        elif soft is not None:
            kind = AssetKind.DEFORMABLE
            cfg = replace(config, max_visual_faces=min(config.max_visual_faces, 800))
            shell = None
            if label in ("towel", "blanket"):
                # cloth lying (maybe folded once): the mass of two layers of cloth over the
                # footprint (the box's walls of cloth thickness), not a block of fabric
                size[2] = max(size[2], 2.0 * soft.thickness_m)
                geometry = ConvexSolids((box_solid([-size[0] / 2, -size[1] / 2, 0.0], [size[0] / 2, size[1] / 2, size[2]]),))
                shell = soft.thickness_m
            elif label in ("pillow", "cushion"):
                geometry = superellipsoid_occupancy(size, min(config.voxel_resolution, 20))
            else:
                geometry = complete_occupancy(pts, cam, size, min(config.voxel_resolution, 20), mirror_y=True, mirror_x=True)
            specs = [PartSpec("body", None, geometry, cm.material, affordance_rank=2, affordance="squeeze or fold",
                              description=f"{label}: soft body", shell_thickness_m=shell, rgba=rgba)]
            description += "; deformable"
        else:
            specs = None

        def assemble(specs, kind, soft, description, cfg, snap=None):
            asset, shift = assemble_asset_with_offset(
                obj.name, label, specs, config=cfg, seed=seed, kind=kind, is_fixed=cat.fixed or obj.built_in, deformable=soft,
                description=description, backend=BACKEND_NAME, observed_points_m=pts, observed_colors_rgb=obj.colors_rgb,
                surface_snap=snap,
            )
            # asset coordinates = box coordinates + shift
            return GeneratedAsset(asset, fit.world_from_box @ pose(np.eye(3), -shift), obj.points_world_m)

        structure_mass_kg = None  # the mass of the category's structure, when its prior is not used
        hidden_prior = ()  # the boxes of a rejected prior fitted to what was seen
        first_fit, refitted, closed = fit, False, True
        while specs is not None:
            generated = assemble(specs, kind, soft, description, cfg)
            samples = transform_points(generated.world_from_asset, surface_samples([q.visual for q in generated.asset.parts], VIOLATION_SAMPLES, seed))
            share = space.violation(samples)
            behind = max([0.0] + [float(-np.min(w.clearance_m(samples))) for w in perception.room.walls])
            if (share <= MAX_FREE_SPACE_SHARE or obj.built_in) and behind <= MAX_BEHIND_WALL_M:
                # (a built-in run stands where its fronts put it, in front of depth that an
                # estimate painted onto the wall behind it: that depth's free space is no evidence)
                return generated
            if rects and closed:
                # Its face left open where no front lies: a box wider than the face its fronts were seen
                # on closes it where the camera saw through (000003's dresser, refitted: 12 % closed, 9 % open).
                closed, specs = False, front_parts(label, size, rects, rgba, close_face=False)
                description += "; its face open where no front was seen"
                continue
            if rects and not refitted and label in ARTICULATED_LABELS and not _held(others, box_from_world, size):
                # Tried once more on the face the fronts were seen on (see face_fitted_box). Not a
                # box that other objects stand inside (a bookcase's books: promptda_arkit's
                # cubbies read as fronts), which is no closed carcass of doors and drawers.
                refitted = True
                fit, size = face_fitted_box(obj, space, cam_world, perception.room.walls, snap_m, blockers, perception.camera, others)
                box_from_world = np.linalg.inv(fit.world_from_box)
                pts = transform_points(box_from_world, obj.points_world_m)
                rects = seen_rectangles(obj.fronts, fit.world_from_box, size, perception.room.walls)
                if rects:  # (front_parts was imported above: there are rects, so fronts)
                    closed = True
                    specs = front_parts(label, size, rects, rgba)
                    description = f"{description.split('; ')[0]}; {len(rects)} fronts seen in the photo; box refitted to their face and the seen free space, " \
                                  f"{size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} m"
                    continue
            what = "front layout" if rects else "articulation template" if label in ARTICULATED_LABELS else "shape prior"
            why = f"filled {share:.0%} seen free space" if share > MAX_FREE_SPACE_SHARE else f"reached {behind * 100:.0f} cm into a wall"
            description = f"{label}: the {what} {why}; " + description.split("; ")[0]
            structure_mass_kg = generated.asset.mass_kg
            # A prior fitted to what was seen (a bed's, a table's) still says what its hidden side
            # holds: the completion fills its boxes too, carved like the shell (a seen overhang
            # of the mattress, a yaw a few degrees off, leave it in seen free space as a whole).
            hidden_prior = tuple((q.vertices_m.min(axis=0), q.vertices_m.max(axis=0)) for part in specs for q in part.geometry.solids) \
                if measured is not None and (measured.back_side is not None or measured.leg_inset_m is not None) else ()
            kind, soft = None, None
            fit = first_fit
            box_from_world = np.linalg.inv(fit.world_from_box)
            pts = transform_points(box_from_world, obj.points_world_m)
            size = fit.size_m.copy()
            break

        voxel_m = float(size.max()) / config.voxel_resolution
        owned = [_ownership(o) for o in other_objects]
        others_tree = cKDTree(np.concatenate([t for t, _, _ in owned])) if others else None
        # Each thinned point's owner's bottom (2nd height percentile): hidden space below an
        # object's observed bottom is never that object's (it rests on what is there).
        others_bottom = np.concatenate([np.full(len(t), bottom) for t, bottom, _ in owned]) if others else None
        own_tree = cKDTree(_ownership(obj)[0])
        walls = perception.room.walls
        # A shelf's column does not carve what stands inside it: books held in an open bookcase
        # stand inside the bookcase's column, and carving them to it left each a sliver of its
        # front face that toppled (promptda_arkit). A bed's or table's column still carves under
        # what lies on it (a pillow lies below a headboard's height, on the bed, not in it).
        # (completion_blockers, found above; _ownership is cached per object)
        columns = [_ownership(o)[2] for o in blocking]

        # Every usable core for the queries (most of the time here), unless objects are made on
        # threads (generation.generate_assets): the other cores are making other objects.
        query_workers = usable_cores() if threading.current_thread() is threading.main_thread() else 1

        def blocked(p_box: np.ndarray) -> np.ndarray:
            """Voxel centres this object may not fill: seen free space, behind a wall, or nearer
            to another object's observed surface than to its own and not below that object's
            bottom (hidden space between two objects is shared out by distance, so their
            completions do not overlap; a supporter keeps its top under what stands on it)."""
            p_world = transform_points(fit.world_from_box, p_box)
            out = space.free(p_world, extra_margin_m=0.5 * voxel_m)
            for wall in walls:
                out |= wall.clearance_m(p_world) < WALL_CLEARANCE_M + 0.5 * voxel_m
            if others_tree is not None:
                d_own, _ = own_tree.query(p_world, workers=query_workers)
                # Another object's surface matters only where it is nearer than this one's.
                bound = float(d_own.max()) + voxel_m
                d_other, idx = others_tree.query(p_world, distance_upper_bound=bound, workers=query_workers)
                near = np.isfinite(d_other)
                above = np.zeros(len(p_world), dtype=bool)
                above[near] = p_world[near, 2] >= others_bottom[idx[near]] - 0.5 * voxel_m
                out |= (d_other < OTHERS_CLEARANCE_M + 0.5 * voxel_m) | ((d_other + 0.5 * voxel_m < d_own) & above)
                # Under something else's top, inside its plan outline: that object's body (a bed
                # under a mat lying on it, whose top the mat hides), unless this object's own
                # surface is right there.
                if columns:
                    import shapely

                    far_own = d_own > 2.0 * voxel_m
                    for outline, z_lo, z_hi in columns:
                        inside = (p_world[:, 2] < z_hi) & (p_world[:, 2] > z_lo) & far_own
                        if np.any(inside):
                            idx = np.flatnonzero(inside)
                            inside[idx] = shapely.contains_xy(outline, p_world[idx, 0], p_world[idx, 1])
                            out |= inside
            return out

        resting, resting_bottom = _resting_on(obj, other_objects, fit.world_from_box, size)
        mirror_x, mirror_y = mirror_axes(label, pts)
        geometry = complete_occupancy(pts, cam, size, config.voxel_resolution, mirror_y=mirror_y, mirror_x=mirror_x, blocked=blocked,
                                      resting_m=resting, resting_bottom_m=resting_bottom, prior_boxes_m=hidden_prior)
        specs = [PartSpec("body", None, geometry, cm.material, affordance_rank=3, affordance="pick up or push",
                          description=f"{label}: observed shell extruded and mirrored", shell_thickness_m=cm.shell_thickness_m,
                          rgba=rgba)]
        description += "; completed from the observed shell" + (f" and the fitted {label} prior" if hidden_prior else "") + ", carved to the seen free space"

        def snap(v_box: np.ndarray) -> np.ndarray:
            return transform_points(box_from_world, space.snap(transform_points(fit.world_from_box, v_box), SNAP_VOXELS * voxel_m))

        out = assemble(specs, None, None, description, config, snap)
        if any(too_small(q.inertial) for q in out.asset.parts):
            # Carved down to a speck MuJoCo cannot simulate (another object seen at the same
            # place took its voxels): the object is the box fitted to its points (1 cm or more).
            box = ConvexSolids((box_solid([-size[0] / 2, -size[1] / 2, 0.0], [size[0] / 2, size[1] / 2, size[2]]),))
            specs = [dataclasses.replace(specs[0], geometry=box, shell_thickness_m=None, description=f"{label}: fitted box")]
            out = assemble(specs, None, None, f"{description.split('; ')[0]}; the fitted box (the completion was carved to a speck)", config)
        if structure_mass_kg is not None and out.asset.mass_kg > structure_mass_kg:
            out = replace(out, asset=with_structure_mass(out.asset, structure_mass_kg))
        return replace(out, asset=replace(out.asset, observed_shape=True))
