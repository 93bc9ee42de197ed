"""The perception stage: photo (and optional depth) in, gravity-aligned camera, room and objects out."""

from __future__ import annotations

from collections.abc import Callable
import dataclasses

import numpy as np

from perception.backends import PerceptionRegistries, build_registries
from perception.bed_foot import split_foot_benches
from perception.headboard import grow_headboards
from perception.inputs import LoadedInput, check_depth, load_input, photo_frame, without_frame
from perception.lying_on import split_lying, top_height, without_points
from perception.naming_prior import GeometricPriorNamer
from perception.protocols import InstanceMasks, keywords_taken
from perception.room import RoomFrame, estimate_room, place_floor_under
from perception.seen_extent import length_max_m
from scene_builder.config import InputSpec, PerceptionConfig
from scene_builder.errors import EmptySceneError, InputError
from scene_builder.frames import cut_by_photo_bottom, transform_points
from scene_builder.model import BackendUse, Camera, CameraIntrinsics, Observation, PerceivedObject, Perception, Room
from scene_builder.vocabulary import category

__all__ = ["BEHIND_WALL_TOLERANCE_M", "CROP_CONTEXT", "MAX_OBJECT_HEIGHT_M", "MIN_OBJECT_HEIGHT_M", "MIN_RAISED_OBJECT_HEIGHT_M", "RAISED_M", "gravity_aligned_size", "perceive"]

#: Clusters lower than this (a rug, a stain of noise on the floor) or taller are not objects.
MIN_OBJECT_HEIGHT_M = 0.03
MAX_OBJECT_HEIGHT_M = 4.0
#: Clusters whose bottom is this far above the floor lie on something; they need only be
#: MIN_RAISED_OBJECT_HEIGHT_M tall (a 2 cm laptop on a cabinet).
RAISED_M = 0.1
MIN_RAISED_OBJECT_HEIGHT_M = 0.01
#: Object points may lie this far behind a wall plane (depth noise, skirting boards).
BEHIND_WALL_TOLERANCE_M = 0.1


def gravity_aligned_size(points_world_m: np.ndarray) -> tuple[float, float, float]:
    """(length, width, height) in metres of (N, 3) world points, length >= width.

    The footprint is the smallest-area yaw-rotated rectangle over 2-degree steps, on the 2nd-98th
    percentiles (robust to stray depth). The height runs from the floor when the object's lowest
    points are within 10 cm of it (a table's legs are often hidden), else from its lowest point.
    """
    p = np.asarray(points_world_m, dtype=np.float64)
    if len(p) > 4000:  # a deterministic stride keeps the percentiles and bounds the cost
        p = p[:: len(p) // 4000 + 1]
    xy = p[:, :2] - p[:, :2].mean(axis=0)
    best = None
    for a in np.radians(np.arange(0.0, 90.0, 2.0)):
        c, s = np.cos(a), np.sin(a)
        u, v = xy @ [c, s], xy @ [-s, c]
        eu = float(np.subtract(*np.percentile(u, [98, 2])))
        ev = float(np.subtract(*np.percentile(v, [98, 2])))
        if best is None or eu * ev < best[0] * best[1]:
            best = (eu, ev)
    lo, hi = np.percentile(p[:, 2], [2, 98])
    bottom = 0.0 if lo < 0.1 else float(lo)
    return max(best), min(best), float(hi - bottom)


def _resolve_depth(
    loaded: LoadedInput, registries: PerceptionRegistries, config: PerceptionConfig
) -> tuple[np.ndarray, CameraIntrinsics, str, list[BackendUse], np.ndarray | None]:
    """Sensor depth, or the depth registry's estimate; returns (H, W) float32 depth, the
    intrinsics (the estimator's focal length when only the default field of view was known),
    the depth source, the BackendUse and the estimator's (3,) up direction in the camera frame
    (None unless it measured one)."""
    k = loaded.intrinsics
    uses = []
    if loaded.depth_m is not None:
        up = loaded.depth_upsampled_from
        said = "sensor depth given" if up is None else f"sensor depth given at {up[0]}x{up[1]} px, upsampled to the photo (bilinear on smooth surfaces, nearest neighbour across depth edges)"
        return loaded.depth_m, k, "sensor", [BackendUse("depth", "sensor", said)], None
    estimator, use = registries.depth.resolve(config.depth_backend)
    uses.append(use)
    known = None if k.source == "default-fov" else k
    est = estimator.estimate(loaded.rgb, known)
    if est.note:
        uses[-1] = BackendUse(use.task, use.backend, f"{use.reason}; {est.note}")
    depth = np.asarray(est.depth_m, dtype=np.float32)
    if depth.shape != loaded.rgb.shape[:2]:
        raise InputError(f"depth backend '{use.backend}' returned {depth.shape[1]}x{depth.shape[0]} depth for a {k.width_px}x{k.height_px} image; choose another --depth-backend")
    depth = np.where(np.isfinite(depth) & (depth > 0), depth, 0.0).astype(np.float32)
    check_depth(depth, f"depth estimated by '{use.backend}'")
    if known is None and est.focal_px is not None and np.isfinite(est.focal_px) and est.focal_px > 0:
        k = CameraIntrinsics(float(est.focal_px), float(est.focal_px), k.cx_px, k.cy_px, k.width_px, k.height_px, "depth-model")
    return depth, k, use.backend, uses, est.up_cam


def _main_clusters(pix: np.ndarray, points_cam: np.ndarray, k: CameraIntrinsics, share: float = 0.1) -> np.ndarray:
    """(H, W) bool: the pixels of ``pix`` whose 3D points belong to a Euclidean cluster holding at
    least ``share`` of them (drops flying pixels and background seen past a mask's edge)."""
    from perception.segment_depth import cluster_points

    idx = np.flatnonzero(pix.reshape(-1))
    labels = cluster_points(points_cam.reshape(-1, 3)[idx], 0.5 * (k.fx_px + k.fy_px))
    sizes = np.bincount(labels)
    out = np.zeros(pix.size, dtype=bool)
    out[idx[sizes[labels] >= share * len(idx)]] = True
    return out.reshape(pix.shape)


#: Naming crops reach this fraction of the mask's box size past each side (min 4 px): a classifier
#: names a chair better with some floor and table around it.
CROP_CONTEXT = 0.15


#: A thing stands on the floor, for naming, when its lowest points (2nd percentile of height) lie
#: within ON_FLOOR_M of it and it rises FLOOR_THING_MIN_HEIGHT_M above them (a book or a bottle
#: on the floor is named by its size as it is).
ON_FLOOR_M = 0.1
FLOOR_THING_MIN_HEIGHT_M = 0.3


def _stands_on_floor(points_world_m: np.ndarray) -> bool:
    lo, hi = np.quantile(points_world_m[:, 2], [0.02, 0.98])
    return bool(lo <= ON_FLOOR_M and hi - lo >= FLOOR_THING_MIN_HEIGHT_M)


def _crop(rgb: np.ndarray, mask: np.ndarray, context: float = CROP_CONTEXT) -> tuple[np.ndarray, np.ndarray]:
    """The (h, w, 3) image crop around ``mask`` ((H, W) bool), its box grown by ``context`` of
    its size on each side and clipped to the image, and the (h, w) mask crop."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    dr, dc = max(4, int(context * (r1 - r0))), max(4, int(context * (c1 - c0)))
    r0, r1, c0, c1 = max(0, r0 - dr), min(mask.shape[0], r1 + dr), max(0, c0 - dc), min(mask.shape[1], c1 + dc)
    return rgb[r0:r1, c0:c1], mask[r0:r1, c0:c1]


def _select_instances(
    labels: np.ndarray,
    points_cam: np.ndarray,
    valid: np.ndarray,
    frame: RoomFrame,
    k: CameraIntrinsics,
    config: PerceptionConfig,
    geometric: bool,
) -> tuple[list[tuple[np.ndarray, np.ndarray]], int, int]:
    """The instances of ``labels`` ((H, W) int, 0 = none) that are objects: enough observed points
    and a plausible height, in front of the walls. Returns (mask, points' pixels) pairs, both
    (H, W) bool, largest first and at most ``config.max_objects``, how many instances were left
    out for lying behind a wall, and how many for having fewer than
    ``config.min_object_points`` measured points off the room's planes (of those whose mask
    holds at least that many pixels: smaller ones are specks, not things left out).

    An image-space mask (a learned segmenter's, ``geometric`` False) bleeds over object edges onto
    the room and onto whatever is behind: its points keep the room out and only the 3D clusters
    that hold a real share of the object (depth clusters are connected by construction).
    """
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    behind_walls = 0
    unmeasured = 0
    area, measured = _pixel_counts(labels, valid & ~frame.background)
    for inst in range(1, len(area)):
        if measured[inst] < config.min_object_points:
            unmeasured += int(area[inst] >= config.min_object_points)
            continue
        mask = labels == inst
        pix = mask & valid & ~frame.background
        if not geometric:
            pix = _main_clusters(pix, points_cam, k)
            if pix.sum() < config.min_object_points:
                unmeasured += 1
                continue
        if frame.room.walls:
            # The room is the space in front of its walls where they stand (their span). What
            # lies mostly behind one, along it, is in the next room, seen through a doorway: not
            # part of this scene. What lies past a wall's end (behind its plane, beside it) is
            # still the room: an L-shaped room, the opening beside a partition (nyuv2_metric3d
            # 00000's table and chairs). Stray points of a kept object behind a wall are trimmed.
            pts_w = transform_points(frame.world_from_camera, points_cam[pix])
            behind = np.zeros(len(pts_w), dtype=bool)
            for wall in frame.room.walls:
                behind |= wall.clearance_m(pts_w) < -BEHIND_WALL_TOLERANCE_M
            if behind.mean() > 0.5:
                behind_walls += 1
                continue
            pix = pix.copy()
            pix[pix] = ~behind
            if pix.sum() < config.min_object_points:
                continue
        z = points_cam[pix] @ frame.up_cam
        lo, hi = np.percentile(z, [2, 98])
        # Thin stuff on the floor is a rug or noise; a thin thing lying on furniture (a laptop,
        # a book) is an object.
        on_furniture = frame.floor_found and float(lo + frame.world_from_camera[2, 3]) > RAISED_M
        if not (MIN_RAISED_OBJECT_HEIGHT_M if on_furniture else MIN_OBJECT_HEIGHT_M) <= hi - lo <= MAX_OBJECT_HEIGHT_M:
            continue
        kept.append((mask, pix))
    kept.sort(key=lambda mp: -int(mp[1].sum()))
    if len(kept) > config.max_objects:
        import warnings

        from scene_builder.errors import InputWarning

        warnings.warn(
            f"{len(kept)} objects found; the {config.max_objects} largest are built and {len(kept) - config.max_objects} smaller ones left out",
            InputWarning,
            stacklevel=3,
        )
    return kept[: config.max_objects], behind_walls, unmeasured


def _pixel_counts(labels: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per instance id of ``labels`` ((H, W), 1-based; index 0 is no instance): its pixels, and
    those of them ``measured`` ((H, W) bool) holds."""
    ids = np.asarray(labels).ravel()
    n = int(ids.max(initial=0)) + 1
    return np.bincount(ids, minlength=n), np.bincount(ids[measured.ravel()], minlength=n)


def _unmeasured_instances(labels: np.ndarray, valid: np.ndarray, background: np.ndarray, min_points: int) -> list[int]:
    """The instances of ``labels`` ((H, W), 1-based) of at least ``min_points`` pixels holding
    fewer than that many measured pixels (``valid``) off the room's planes (``background``):
    the ones :func:`_select_instances` leaves out as unmeasured by the same counts."""
    area, measured = _pixel_counts(labels, valid & ~background)
    return [i for i in range(1, len(area)) if area[i] >= min_points and measured[i] < min_points]


def _fill_silhouettes(kept: list[tuple[np.ndarray, np.ndarray]], labels: np.ndarray, free: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each mask with its enclosed holes filled where the hole is ``free`` ((H, W) bool: room or
    no depth) and in no instance of ``labels``; a pixel goes to the first (largest) mask only.

    A bookcase's back panel lies in the wall plane and so is taken for wall; the wall seen through
    an open back or between a chair's slats is inside the object's silhouette too. The object's
    mask is its silhouette (what render-and-compare scores); its points stay as observed.
    """
    from scipy.ndimage import binary_fill_holes

    claimed = labels > 0
    out = []
    for mask, pix in kept:
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))  # holes lie inside it
        m = mask[box]
        add = binary_fill_holes(m) & ~m & free[box] & ~claimed[box]
        mask = mask.copy()
        mask[box] |= add
        claimed[box] |= add
        out.append((mask, pix))
    return out


def _instance_id(mask: np.ndarray, labels: np.ndarray) -> int:
    """The instance of ``labels`` under ``mask`` ((H, W) bool; silhouettes add unlabelled pixels),
    0 if none."""
    ids = labels[mask]
    ids = ids[ids > 0]
    return int(np.bincount(ids).argmax()) if len(ids) else 0


def _given_name(mask: np.ndarray, labels: np.ndarray, masks: InstanceMasks) -> tuple[str, float] | None:
    """(label, score) the segmenter gave the instance under ``mask`` ((H, W) bool), or None."""
    given = getattr(masks, "names", None)
    inst = _instance_id(mask, labels)
    if given is None or inst == 0 or inst > len(given) or not given[inst - 1]:
        return None
    return given[inst - 1], float(masks.scores[inst - 1])


#: A fragment joins the object it belongs to when this share of its points lies inside that
#: object's footprint (the convex hull of its points in plan) and it comes within FRAGMENT_GAP_M
#: of its points.
FRAGMENT_INSIDE = 0.8
FRAGMENT_GAP_M = 0.05
#: Furniture whose fragments are merged (small things of one family, a vase beside a mug, are not:
#: one's footprint often holds the other's).
FRAGMENT_LABELS = frozenset({"sofa", "bench", "bed", "table", "desk", "cabinet", "drawer_unit", "wardrobe"})


def _merge_fragments(
    kept: list[tuple[np.ndarray, np.ndarray]], points_world: list[np.ndarray], names: list[tuple[str, float]]
) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray], list[tuple[str, float]], int]:
    """One object per real thing: a smaller object named in the family of a larger one (a seat or
    bed, a table or desk, a cabinet: :data:`perception.detection.FAMILIES`) whose points lie in
    the larger's footprint and touch them is a fragment of it (a sleigh bed's mattress, cut apart
    from its frame by a depth edge, which the detector boxed as a table and the classifier named
    a bed); the two become one object, named by the fragment named with more confidence (the
    frame alone looked like a sofa to both models). Pillows and things of other families on a
    bed stay objects. Returns the kept masks and pixels, points, names and the merge count.
    kept: (silhouette mask, mask of the pixels with points) per object, both (H, W) bool;
    points_world: (N, 3) per object; names: (label, conf)."""
    from scipy.spatial import Delaunay, QhullError, cKDTree

    from perception.detection import family

    order = sorted(range(len(kept)), key=lambda i: -len(points_world[i]))
    gone: set[int] = set()
    kept, points_world, names = list(kept), list(points_world), list(names)
    for host in order:
        if host in gone or names[host][0] not in FRAGMENT_LABELS:
            continue
        for frag in order:
            if frag == host or frag in gone or names[frag][0] not in family(names[host][0]):
                continue
            ph, pf = points_world[host], points_world[frag]
            if len(pf) > len(ph) or len(ph) < 4 or len(pf) < 4:
                continue
            try:
                hull = Delaunay(ph[:: max(1, len(ph) // 3000), :2])
            except QhullError:  # a host whose footprint is a line has no inside
                continue
            sub = pf[:: max(1, len(pf) // 2000)]
            inside = hull.find_simplex(sub[:, :2]) >= 0
            if inside.mean() < FRAGMENT_INSIDE:
                continue
            gap, _ = cKDTree(ph[:: max(1, len(ph) // 20000)]).query(sub, k=1, distance_upper_bound=FRAGMENT_GAP_M)
            if not np.any(np.isfinite(gap)):
                continue
            mask = kept[host][0] | kept[frag][0]
            kept[host] = (mask, kept[host][1] | kept[frag][1])
            points_world[host] = np.concatenate([ph, pf])  # for the next fragment; the caller recomputes them in pixel order
            if names[frag][1] > names[host][1]:
                names[host] = names[frag]
            gone.add(frag)
    keep = [i for i in range(len(kept)) if i not in gone]
    return [kept[i] for i in keep], [points_world[i] for i in keep], [names[i] for i in keep], len(gone)


#: Labels whose object ends at its top surface (found by ``perception.lying_on.top_height``);
#: points more than ABOVE_TOP_M above its height (depth noise, a top's lip) are not the table's.
TOPPED = frozenset({"table", "desk"})
ABOVE_TOP_M = 0.04


def _cut_above_tops(
    kept: list[tuple[np.ndarray, np.ndarray]], points_world: list[np.ndarray], labels: list[str]
) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray], int]:
    """A table or desk is what lies at and under its top: a detector's box and the cut in it take
    what rises behind (the partition panel behind an office desk, 60 cm over the desk top), and
    a table completed up to that height swallows what stands on it. The top is the highest dense
    band of heights (``perception.lying_on.top_height``); the points more than
    :data:`ABOVE_TOP_M` above it leave the object's points and
    mask (they are background). Objects with no such band (a table seen edge-on) are unchanged.
    Returns the kept masks and pixels, the points and the number of objects cut."""
    out_kept, out_points, cut = list(kept), list(points_world), 0
    for i, (label, pts) in enumerate(zip(labels, points_world)):
        if label not in TOPPED or len(pts) < 50:
            continue
        z = pts[:, 2]
        top = top_height(z)  # the top surface's height
        if top is None:
            continue
        drop = z > top + ABOVE_TOP_M
        if not np.any(drop):
            continue
        out_kept[i], out_points[i] = without_points(*kept[i], pts, drop)
        cut += 1
    return out_kept, out_points, cut


#: An object whose plan is this many times its category's largest typical dimension took in
#: what was seen past it; its clusters SEEN_THROUGH_M or more behind its largest one are cut.
SEEN_THROUGH_SIZE_FACTOR = 2.0
SEEN_THROUGH_M = 0.5


def _seen_through(points_cam: np.ndarray, focal_px: float) -> np.ndarray:
    """(N,) bool: the points of an object's Euclidean clusters whose median depth lies
    :data:`SEEN_THROUGH_M` or more beyond the farthest (98th percentile) points of its largest
    cluster."""
    from scipy import ndimage

    from perception.segment_depth import cluster_points

    labels = cluster_points(points_cam, focal_px)
    sizes = np.bincount(labels)
    if len(sizes) < 2:
        return np.zeros(len(points_cam), dtype=bool)
    z = points_cam[:, 2]
    far = float(np.percentile(z[labels == int(np.argmax(sizes))], 98))
    medians = np.asarray(ndimage.median(z, labels, np.arange(len(sizes))))
    return medians[labels] > far + SEEN_THROUGH_M


def _cut_seen_through(
    kept: list[tuple[np.ndarray, np.ndarray]], points_world: list[np.ndarray], labels: list[str], points_cam: np.ndarray, focal_px: float
) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray], int]:
    """A mask (a detection's cut, a learned segmenter's) can take in what is seen through or past
    the object: the sofa through a dining chair's open back made a "chair" 3.5 m deep
    (multiview frame 3 of ../shared/data/multiview), whose shape prior then filled the room
    between them. An object whose plan is :data:`SEEN_THROUGH_SIZE_FACTOR` times its category's
    largest typical dimension or more loses the clusters lying well behind its largest one
    (:func:`_seen_through`; points and mask pixels: they are what lies behind). A bed seen from
    its foot, whose mattress lies behind a footboard, is within its size and untouched.
    Returns the kept masks and pixels, the points and the number of objects cut."""

    out_kept, out_points, cut = list(kept), list(points_world), 0
    for i, (label, pts) in enumerate(zip(labels, points_world)):
        plan = max(gravity_aligned_size(pts)[:2])
        if label == "object" or plan < SEEN_THROUGH_SIZE_FACTOR * max(category(label).typical_size_m):
            continue
        drop = _seen_through(points_cam[kept[i][1]], focal_px)
        if drop.any() and not drop.all():
            out_kept[i], out_points[i] = without_points(*kept[i], pts, drop)
            cut += 1
    return out_kept, out_points, cut


def perceive(inputs: InputSpec, config: PerceptionConfig, seed: int = 0, on_step: Callable[[str], None] | None = None) -> Perception:
    """Load and check the input, find gravity, floor, walls and the objects.

    on_step: called with a short text as each step starts (the CLI shows it live).
    Raises InputError for unusable input and EmptySceneError when no object is found.
    """
    step = on_step or (lambda _text: None)
    step("loading the photo")
    loaded = load_input(inputs, config)
    registries = build_registries(config)
    size = f"{loaded.rgb.shape[1]}x{loaded.rgb.shape[0]}" + (f" (from {loaded.rgb_full.shape[1]}x{loaded.rgb_full.shape[0]})" if loaded.rgb_full is not None else "")
    step(f"depth, {size}" if loaded.depth_m is not None else f"estimating depth from the photo, {size}")
    depth_m, k, depth_source, backends, up_hint = _resolve_depth(loaded, registries, config)
    backends.insert(0, BackendUse("intrinsics", k.source, f"{k.fx_px:.1f} px focal length ({k.width_px}x{k.height_px})"))
    # The photo's textures without its flat frame (undistortion padding); what is analysed keeps it.
    frame_px = photo_frame(loaded.rgb)
    rgb, rgb_full = loaded.rgb, loaded.rgb_full
    if any(frame_px):
        rgb = without_frame(rgb, frame_px)
        rgb_full = None if rgb_full is None else without_frame(rgb_full, photo_frame(rgb_full))
        backends.append(BackendUse("photo-frame", "flat-border", f"a flat frame around the photo ({'/'.join(map(str, frame_px))} px top/bottom/left/right) textured with the pixels inside it"))
    observation = Observation(str(loaded.image_path), rgb, depth_m, k, depth_source, rgb_full)

    points_cam = k.unproject(depth_m)
    valid = (depth_m > 0) & (depth_m < config.max_depth_m)
    step(f"gravity, floor and walls (depth: {depth_source})")
    frame = estimate_room(points_cam, valid, seed, up_hint=up_hint)
    backends.append(frame.gravity)

    segmenter, seg_use = registries.segmentation.resolve(config.segmentation_backend)
    backends.append(seg_use)
    step(f"segmenting objects ({seg_use.backend})")
    geometric = bool(getattr(segmenter, "accepts_gravity", False))
    extra = {"depth_measured": depth_source == "sensor"} if getattr(segmenter, "accepts_depth_source", False) else {}
    if geometric:
        masks: InstanceMasks = segmenter.segment(loaded.rgb, depth_m, k, frame.background, up_cam=frame.up_cam, **extra)
    else:
        masks = segmenter.segment(loaded.rgb, depth_m, k, frame.background, **extra)
    labels = np.asarray(masks.labels)
    if labels.shape != depth_m.shape:
        raise InputError(f"segmentation backend '{seg_use.backend}' returned masks of shape {labels.shape} for a {depth_m.shape} image; choose another --segmentation-backend")
    backends.extend(getattr(segmenter, "uses", ()))
    removed = getattr(masks, "removed", None)
    if removed is not None and not np.any(removed):
        removed = None
    if removed is not None:
        share = 100.0 * float(np.mean(removed))
        backends.append(BackendUse("people", seg_use.backend, f"removed {getattr(masks, 'removed_count', 0)} people or animals ({share:.0f} % of the photo): not part of the room; the background fills what they hid"))
    given_names = getattr(masks, "names", None)
    lifted: tuple[int, ...] = ()
    if given_names is not None and frame.floor_found:
        # Estimated depth may put a detected object on the room's planes, and a sensor may not
        # measure one (too dark or far for it, or a sparse scan: sunrgbd_000017's chest of
        # drawers holds 53 measured points on 8343 pixels): it stands at its floor contact.
        # Sensor depth stands wherever it measured enough of an object to build it.
        from perception.contact import stand_on_contacts

        # (with sensor depth, what stands on the floor: a mirror the sensor sees through, boxed
        # as a tv, is no object standing on the dresser under it)
        only = None if depth_source != "sensor" else frozenset(
            i for i in _unmeasured_instances(labels, valid, frame.background, config.min_object_points)
            if i <= len(given_names) and given_names[i - 1] and category(given_names[i - 1]).on_floor
        )
        if only is None or only:
            obj_depth, valid, background, labels, lifted = stand_on_contacts(
                depth_m, valid, frame.background, labels, given_names, frame.world_from_camera, k, config.max_depth_m,
                getattr(masks, "boxes_xyxy_px", None), frame.room.walls, only=only, square_to_walls=only is not None,
            )
        if lifted:
            points_cam = k.unproject(obj_depth)
            frame = dataclasses.replace(frame, background=background)
            # The estimate, where an object stands, is the object's depth: generation carves
            # each shape to what the camera saw in front of the observed depth, and the room's
            # planes behind a lifted object would carve it away (a refrigerator standing 2 m
            # before the wall estimate kept only the half its contact left).
            observation = dataclasses.replace(observation, depth_m=np.asarray(obj_depth, dtype=np.float32))
            missed = "estimated depth missed" if depth_source != "sensor" else "sensor depth did not measure"
            backends.append(BackendUse("placement", "floor-contact", f"{len(lifted)} detected objects the {missed} stand at their floor contact"))

    kept, behind_walls, unmeasured = _select_instances(labels, points_cam, valid, frame, k, config, geometric)
    kept = _fill_silhouettes(kept, labels, frame.background | ~valid)
    if behind_walls:
        backends.append(BackendUse("walls", "room-planes", f"{len(frame.room.walls)} walls; left out {behind_walls} objects behind them (in the next room)"))
    if unmeasured:
        backends.append(BackendUse("segmentation", seg_use.backend, f"left out {unmeasured} segmented objects with fewer than {config.min_object_points} measured depth points off the room's planes (too dark, far or thin for the depth to build them)"))
    if not kept:
        raise EmptySceneError(
            f"no objects found in {loaded.image_path}: nothing stands out from the floor and walls; "
            "photograph the objects from 1-4 m with the floor in view, or pass a depth map with --depth"
        )
    if not frame.floor_found:
        lowest = min(float(np.quantile(transform_points(frame.world_from_camera, points_cam[pix])[:, 2], 0.01)) for _, pix in kept)
        frame = place_floor_under(frame, lowest)
    if frame.floor is not None:
        backends.append(frame.floor)

    namer, name_use = registries.naming.resolve(config.naming_backend)
    backends.append(name_use)
    step(f"naming {len(kept)} objects ({name_use.backend})")

    # Left to right (mask centroid column, then row) for a stable, readable numbering.
    def centroid(mp):
        rr, cc = np.nonzero(mp[0])
        return (float(cc.mean()), float(rr.mean()))

    kept.sort(key=centroid)
    points_world = [transform_points(frame.world_from_camera, points_cam[pix]) for _, pix in kept]
    sizes = [gravity_aligned_size(p) for p in points_world]
    # An object the photo's bottom edge cut (a sideboard filling the bottom corner) is taller than
    # it was seen, by at most down to the floor: named over that range of heights (when the floor
    # was seen: a floor put under what was seen says nothing of what is below the photo). A piece
    # of furniture a side edge cut (a dresser at the photo's edge) is longer than seen: named over
    # a range of lengths (perception.seen_extent).
    tops = [float(np.quantile(p[:, 2], 0.99)) if frame.floor_found and cut_by_photo_bottom(mask, valid) else None for (mask, _), p in zip(kept, points_world)]
    spans = [length_max_m(mask, s) for (mask, _), s in zip(kept, sizes)]
    # A thing of furniture height standing on the floor is named as one (no monitor or vase:
    # perception.naming_prior.OFF_FLOOR_WEIGHT), where the floor was seen.
    floors = [frame.floor_found and _stands_on_floor(p) for p in points_world]

    def bounds(ids: list[int], one: bool = False) -> dict:
        """The namer's keyword arguments for objects ``ids`` that have them: per object
        (``heights_max_m``, ``lengths_max_m``), or for one (``height_max_m``, ``length_max_m``)."""
        out = {f"{what}{'' if one else 's'}_max_m": vals[ids[0]] if one else [vals[i] for i in ids]
               for what, vals in (("height", tops), ("length", spans)) if any(vals[i] is not None for i in ids)}
        if any(floors[i] for i in ids):
            out["on_floor"] = floors[ids[0]] if one else [floors[i] for i in ids]
        return out

    crops = [_crop(loaded.rgb, mask) for mask, _ in kept]
    # Names the segmenter knows (a detector's class) come first; the naming backend names the rest.
    names: list[tuple[str, float] | None] = [_given_name(mask, labels, masks) for mask, _ in kept]
    # A weak detection (under the detector's trust score, confirmed by depth or the semantic map)
    # says something is there; its class is a guess (the Open Images SSD calls a sideboard a
    # table): the naming backend names it, the detector's class standing in where it says "object".
    from perception.detection import CONFIDENT

    guessed = {i: n for i, n in enumerate(names) if n is not None and n[1] < CONFIDENT}
    for i in guessed:
        names[i] = None
    todo = [i for i, n in enumerate(names) if n is None]
    if todo and hasattr(namer, "name_many"):  # a learned namer runs all crops in one batch
        # (a namer is asked without the bounds no object has, or that it does not take: a plug-in)
        for i, n in zip(todo, namer.name_many([crops[i][0] for i in todo], [crops[i][1] for i in todo], [sizes[i] for i in todo],
                                              **keywords_taken(namer.name_many, **bounds(todo)))):
            names[i] = n
    else:
        for i in todo:
            names[i] = namer.name(crops[i][0], crops[i][1], sizes[i], **keywords_taken(namer.name, **bounds([i], one=True)))
    for i, n in guessed.items():
        if names[i][0] == "object":
            names[i] = n
    if len(todo) < len(kept):
        # A detector's class names a kind of thing (a seat or bed, a table or desk); the size and
        # the classifier pick the member of its family (a sleigh bed the detector calls a couch).
        from perception.detection import refine_in_family

        # (Not for objects stood on their floor contact: their depth, so their size, is a guess.)
        given = [i for i in range(len(kept)) if i not in todo and _instance_id(kept[i][0], labels) not in lifted]
        refined = refine_in_family(namer, [names[i] for i in given], [crops[i] for i in given], [sizes[i] for i in given], [tops[i] for i in given], [spans[i] for i in given])
        for i, n in zip(given, refined):
            names[i] = n
        backends.append(
            BackendUse("naming", seg_use.backend, f"{len(kept) - len(todo)} of {len(kept)} objects named by the segmenter (a detector's class, or the classifier's where the detector was unsure)")
        )
    # A namer that weighs no size evidence (a plug-in classifier) may leave objects as "object":
    # the size prior names those (an honest, low-confidence label is more use to generation than
    # "object"), recorded as a second naming entry. The learned namers here already combine
    # both into one posterior and answer "object" only where the prior would too.
    named_by_prior = 0
    if name_use.backend != "geometric-prior":
        prior = GeometricPriorNamer()
        for i in todo:
            (c, m), s = crops[i], sizes[i]
            if names[i][0] == "object" and (guess := prior.name(c, m, s, on_floor=floors[i]))[0] != "object":
                names[i] = guess
                named_by_prior += 1
    kept, points_world, names, merged = _merge_fragments(kept, points_world, names)
    if merged:
        points_world = [transform_points(frame.world_from_camera, points_cam[pix]) for _, pix in kept]
        backends.append(BackendUse("fragments", "family-footprint", f"merged {merged} fragments into the object of one family they lie on (a mattress on its bed frame)"))
    kept, points_world, through = _cut_seen_through(kept, points_world, [n for n, _ in names], points_cam, 0.5 * (k.fx_px + k.fy_px))
    if through:
        backends.append(BackendUse("seen-through", "depth-clusters", f"{through} objects far larger than their kind lost what was seen past them (clusters {SEEN_THROUGH_M} m or more behind)"))
    kept, points_world, cut = _cut_above_tops(kept, points_world, [n for n, _ in names])
    if cut:
        backends.append(BackendUse("table-tops", "height-layers", f"{cut} tables or desks kept to their top: what rose above it (a partition behind a desk) is background"))
    kept, points_world, names, benches = split_foot_benches(kept, points_world, names)
    if benches:
        backends.append(BackendUse("bed-foot", "height-layers", f"{benches} benches at the foot of a bed cut out of it as objects"))
    kept, points_world, names, pillows = split_lying(kept, points_world, names)
    if pillows:
        backends.append(BackendUse("lying-on", "height-layers", f"{pillows} pillows lying on a bed or sofa cut out of it as objects"))
    headboards = 0
    if any(label == "bed" for label, _ in names):  # (the whole image's world points and rays: only for a bed)
        world_img = transform_points(frame.world_from_camera, points_cam.reshape(-1, 3)).reshape(points_cam.shape)
        rays_world = k.unproject(np.ones(depth_m.shape)) @ frame.world_from_camera[:3, :3].T
        kept, points_world, headboards = grow_headboards(kept, points_world, names, world_img, valid, frame.room.walls, rays_world,
                                                         frame.world_from_camera[:3, 3])
    if headboards:
        backends.append(BackendUse("headboards", "wall-offset", f"{headboards} beds grown over the headboard standing off the wall at their head (the room's planes had taken it as wall)"))
    per_label: dict[str, int] = {}
    objects = []
    for object_id, ((mask, pix), points_w, (label, conf)) in enumerate(zip(kept, points_world, names), start=1):
        per_label[label] = per_label.get(label, 0) + 1
        objects.append(
            PerceivedObject(
                object_id=object_id,
                name=f"{label}_{per_label[label]}",
                label=label,
                label_confidence=float(np.clip(conf, 0.0, 1.0)),
                mask=mask,
                points_world_m=points_w,
                colors_rgb=loaded.rgb[pix],
            )
        )
    if named_by_prior:
        backends.append(BackendUse("naming", "geometric-prior", f"named {named_by_prior} of {len(objects)} objects that '{name_use.backend}' left as 'object'"))
    camera = Camera(k, frame.world_from_camera)
    room = frame.room
    if config.fronts:  # door and drawer fronts on the furniture's faces; built-in runs found from their fronts
        from perception.built_in import fronts_and_built_ins

        objects, front_use = fronts_and_built_ins(tuple(objects), observation, camera, room.walls, removed)
        backends.append(front_use)
    if config.background:
        from perception.background import observed_background
        from perception.room import completion_planes

        bg = observed_background(observation, camera, room.walls, tuple(objects), config.max_depth_m, removed=removed, extra_planes=completion_planes(frame))
        room = Room(walls=room.walls, background=bg)
        if bg.closed_sides:
            from perception.room_surfaces import BOX_CLEARANCE_M, CAMERA_MARGIN_M

            backends.append(BackendUse("room-closure", "room-box", f"{bg.closed_sides} sides of the room with no wall seen closed by a wall {BOX_CLEARANCE_M * 100:.0f} cm past the farthest point seen "
                                       f"(at least {CAMERA_MARGIN_M} m beside the camera; a guess, drawn only)"))
    return Perception(observation, camera, room, tuple(objects), tuple(backends), removed_mask=removed, left_out_behind_walls=behind_walls,
                      left_out_unmeasured=unmeasured)

