"""Detected objects stand at the depth of their floor contact (plain photos).

Estimated single-photo depth can miss an object a detector sees: a coarse geometric estimate
puts its pixels on the floor or a wall (the room's planes then claim them), or gives them no
depth. Such an object stands where its outline meets the floor: each bottom pixel of its mask
(the lowest mask pixel of each column, or the detector box's bottom edge when lower) is cast
onto the floor plane, and the object becomes a vertical face, turned to the camera, through the
median contact point. Where another object hides the contact, it lies between that object's back
and the floor under the visible bottom, at the distance that gives the object its category's
typical height; where the frame cuts the object, it stands at the floor under the frame's edge (generation completes
the unseen depth from the category's proportions). What does not stand on the floor (a tv on a
cabinet, a book on a table) takes the depth found just under its outline: the object already
lifted there, else the estimated depth. An object the estimate does see (half its pixels off the
room planes) keeps its estimated depth.

With sensor depth, ``perceive`` asks this only for the detected objects the sensor measured too
little of to build (``only``): the depth it measured elsewhere is never changed.
"""

from __future__ import annotations

import numpy as np

from scene_builder.model import CameraIntrinsics
from scene_builder.vocabulary import category

__all__ = ["LEGGED", "SEES_SHARE", "stand_on_contacts"]

#: An object whose mask has this share of off-room depth is seen by the estimate: left as it is.
SEES_SHARE = 0.5
#: A lifted object's face is square to the walls when that turns it less than this from facing the camera.
FACE_WALL_DEG = 40.0
#: An object whose estimated points lie on one vertical plane (spread across it under
#: EDGE_ON_SPREAD_M) turned within EDGE_ON_DEG of the camera's heading, all of them at least
#: EDGE_ON_MIN_HEIGHT_M above the floor, was painted onto a side wall of the estimate's room box
#: (sunrgbd_total3d_demo_4's back-left desk: a plane 1.2 m left of the camera, 0.8-1.2 m up,
#: 1.9-3.5 m ahead): the estimate did not see it, whatever share of its pixels is off the planes.
EDGE_ON_SPREAD_M = 0.03
EDGE_ON_DEG = 30.0
EDGE_ON_MIN_HEIGHT_M = 0.3
#: Categories that stand on legs: what lies under their top is mostly floor.
LEGGED = frozenset({"table", "desk", "chair", "stool", "bench"})


def _rays(k: CameraIntrinsics, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame rays with z = 1 through pixel centres (u, v)."""
    return np.stack([(u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, np.ones_like(u, dtype=np.float64)], axis=1)


def _face_depth(mask: np.ndarray, contact_cam: np.ndarray, up_cam: np.ndarray, k: CameraIntrinsics, wall_normals_cam: tuple = ()) -> np.ndarray:
    """Planar depth of the mask's pixels on the vertical plane through ``contact_cam`` (3,) that
    faces the camera (its normal is the horizontal direction from the camera to the contact), or
    that is square to the walls (``wall_normals_cam``: the walls' normals in the camera frame;
    the plane's normal one of them or a direction along a wall) turned less than FACE_WALL_DEG
    from that: furniture stands square to the room (a chest of drawers seen 34 degrees off its
    face against the wall beside the one found, sunrgbd_000017_mmdet3d)."""
    n = contact_cam - (contact_cam @ up_cam) * up_cam
    n /= max(np.linalg.norm(n), 1e-9)
    # the room's horizontal axes: each wall's normal and the direction along the wall
    axes = []
    for wn in wall_normals_cam:
        wn = np.asarray(wn, dtype=np.float64)
        wn = wn - (wn @ up_cam) * up_cam
        wn /= max(np.linalg.norm(wn), 1e-9)
        along = np.cross(up_cam, wn)
        axes += [wn, -wn, along, -along]
    if axes:
        best = max(axes, key=lambda a: float(a @ n))
        if best @ n >= np.cos(np.radians(FACE_WALL_DEG)):
            n = best
    rr, cc = np.nonzero(mask)
    rays = _rays(k, cc.astype(np.float64), rr.astype(np.float64))
    denom = rays @ n
    z = np.where(denom > 1e-3, float(n @ contact_cam) / np.maximum(denom, 1e-3), 0.0)
    return z


def _floor_distance(rays: np.ndarray, rot: np.ndarray, cam: np.ndarray, max_depth_m: float) -> np.ndarray:
    """Planar depth at which each (N, 3) z = 1 camera ray meets the floor (inf where it does not)."""
    dz = rays @ rot[2]  # world z per unit of planar depth
    s = np.full(len(rays), np.inf)
    down = dz < -1e-6
    s[down] = -cam[2] / dz[down]
    s[(s < 0.2) | (s > max_depth_m)] = np.inf
    return s


def _height_distance(ray: np.ndarray, rot: np.ndarray, cam: np.ndarray, height_m: float) -> float:
    """Planar depth at which the z = 1 camera ``ray`` reaches ``height_m`` above the floor (inf
    when it runs nearly level: the top of the object is near the camera's height)."""
    dz = float(ray @ rot[2])
    if abs(dz) < 0.05:
        return np.inf
    s = (height_m - cam[2]) / dz
    return s if s > 0.3 else np.inf


def _painted_edge_on(points_world_m: np.ndarray, heading: np.ndarray) -> bool:
    """Whether the (N, 3) world points of an object lie on one vertical plane near the camera's
    horizontal ``heading`` (unit (2,)), off the floor (:data:`EDGE_ON_SPREAD_M`)."""
    p = np.asarray(points_world_m, dtype=np.float64)
    if len(p) < 50 or float(np.percentile(p[:, 2], 5)) < EDGE_ON_MIN_HEIGHT_M:
        return False
    xy = p[:, :2] - p[:, :2].mean(axis=0)
    ev, evec = np.linalg.eigh(np.cov(xy.T))
    if np.sqrt(max(ev[0], 0.0)) > EDGE_ON_SPREAD_M or np.sqrt(ev[1]) < 4 * EDGE_ON_SPREAD_M:
        return False
    return abs(float(evec[:, 1] @ heading)) >= np.cos(np.radians(EDGE_ON_DEG))


def _in_front_of_walls(ray: np.ndarray, s: float, rot: np.ndarray, cam: np.ndarray, walls, margin_m: float = 0.15) -> float:
    """``s`` shortened so that the point at planar depth ``s`` on ``ray`` stays ``margin_m`` in
    front of every wall it would pass where the wall stands (a ray past a wall's end goes on; a
    coarse room box may stand its walls too near)."""
    d = rot @ ray
    for wall in walls:
        n = np.asarray(wall.normal, dtype=np.float64)
        rate = float(n @ d)
        if rate < -1e-6:
            s_wall = (margin_m - float(n @ cam) - float(wall.offset_m)) / rate
            if s_wall > 0.3 and np.isfinite(wall.clearance_m(cam + s_wall * d)[0]):
                s = min(s, s_wall)
    return s


def stand_on_contacts(
    depth_m: np.ndarray,
    valid: np.ndarray,
    background: np.ndarray,
    labels: np.ndarray,
    names: tuple[str, ...],
    world_from_camera: np.ndarray,
    k: CameraIntrinsics,
    max_depth_m: float = 10.0,
    boxes_xyxy_px: np.ndarray | None = None,
    walls=(),
    only: frozenset[int] | None = None,
    square_to_walls: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[int, ...]]:
    """Object depth for the named instances the estimated depth does not see.

    depth_m: (H, W) estimated depth; valid, background: (H, W) bool; labels: (H, W) instance ids
    (1-based); names: vocabulary label of each instance (``""`` = not detected, left alone);
    world_from_camera: (4, 4) with the floor at z = 0; boxes_xyxy_px: None or (K, 4) detector
    boxes (NaN rows for none): a box's bottom edge is the floor contact when it is below the
    mask's (thin legs, a foot the cut lost); walls: the room's walls (world planes), which the
    objects stay in front of; only: the instance ids to consider (None: every named one);
    square_to_walls: a floor-standing object's face is square to the walls (measured walls; a
    single-view estimate's walls are guesses: its objects face the camera).
    Where another instance hides the contact, or the frame cuts the
    object, the distance at which the object's top is at its category's typical height decides
    within the bounds the view leaves (see the module doc); a visible contact that gives the
    object a height no thing of its kind has (under 0.4 or over 2.5 times typical) gives way to
    that distance too.

    A solid floor-standing object's mask (not :data:`LEGGED`) grows down to its box's bottom
    edge through pixels no other instance holds (what the cut left of it between its outline and
    its contact).

    Returns the object depth (H, W) float32, valid, background and labels updated for the
    lifted instances, and the ids of the lifted instances.
    """
    depth = np.asarray(depth_m, dtype=np.float64).copy()
    valid = valid.copy()
    background = background.copy()
    labels = np.asarray(labels).copy()
    rot, cam = world_from_camera[:3, :3], world_from_camera[:3, 3]
    up_cam = rot.T @ np.array([0.0, 0.0, 1.0])
    h, w = depth.shape
    ids = [i + 1 for i, n in enumerate(names) if n and (only is None or i + 1 in only)]
    lowest = {i: int(np.flatnonzero((labels == i).any(axis=1)).max(initial=-1)) for i in ids}
    # Floor-standing things first, nearest (lowest in the image) first: an occluder is placed
    # before what it hides, and what stands on things looks for its support under its outline.
    ids.sort(key=lambda i: (not category(names[i - 1]).on_floor, -lowest[i], i))
    lifted: list[int] = []
    wall_normals_cam = tuple(rot.T @ np.asarray(wl.normal, dtype=np.float64) for wl in walls)
    heading = rot[:2, 2] / max(float(np.linalg.norm(rot[:2, 2])), 1e-9)
    for inst in ids:
        mask = labels == inst
        area = int(mask.sum())
        label = names[inst - 1]
        seen = mask & valid & ~background
        if area == 0 or (seen.sum() >= SEES_SHARE * area and not (
                category(label).on_floor and _painted_edge_on(k.unproject(depth)[seen] @ rot.T + cam, heading))):
            continue
        cols = np.flatnonzero(mask.any(axis=0))
        bottom = (h - 1 - np.argmax(mask[::-1, cols], axis=0)).astype(np.float64)
        top = np.argmax(mask[:, cols], axis=0).astype(np.float64)
        # What is right under the outline: another object there hides the floor contact.
        under_r = np.clip(bottom.astype(np.int64) + 3, 0, h - 1)
        under = labels[under_r, cols]
        box = None if boxes_xyxy_px is None else np.asarray(boxes_xyxy_px[inst - 1], dtype=np.float64)
        if box is not None and np.all(np.isfinite(box)):
            bottom = np.maximum(bottom, min(box[3], h) - 1.0)
        contact = None
        if category(label).on_floor:
            rays = _rays(k, cols.astype(np.float64), bottom + 0.5)
            s = _floor_distance(rays, rot, cam, max_depth_m)
            hit = np.isfinite(s)
            if hit.mean() >= 0.5:
                s_floor = float(np.median(s[hit]))
                mid = _rays(k, np.array([float(np.median(cols))]), np.array([float(np.percentile(top, 10))]))[0]
                typical = category(label).typical_size_m
                s_top = _height_distance(mid, rot, cam, typical[2])
                if typical[2] < min(typical[:2]):
                    # A low, deep thing (a bed, a table) shows its far edge at the top of its
                    # outline: its front is about its depth nearer.
                    s_top -= min(typical[:2])
                occluders = under[(under > 0) & (under != inst)]
                if len(occluders) >= 0.5 * len(cols):
                    # Hidden behind another object: the contact lies between that object's back
                    # (its depth plus its category's typical depth) and the floor under the
                    # visible bottom; the typical height picks the distance in between.
                    occ = int(np.bincount(occluders).argmax())
                    occ_z = depth[labels == occ]
                    occ_z = occ_z[occ_z > 0]
                    back = float(np.median(occ_z)) if len(occ_z) else 0.0
                    if 0 < occ <= len(names) and names[occ - 1]:
                        back += min(category(names[occ - 1]).typical_size_m[:2])
                    if np.isfinite(s_top) and back < s_floor:
                        s_floor = float(np.clip(s_top, back, s_floor))
                elif float(bottom.max()) >= h - 2:
                    # Cut by the frame: the contact is below the photo, no farther than the floor
                    # at its edge (the nearest the view allows).
                    pass
                else:
                    # The contact is in view: trusted, unless it gives the object a height no
                    # thing of its kind has (a foot the cut lost and the box missed).
                    seen_h = float(cam[2] + s_floor * (mid @ rot[2]))
                    if not 0.4 <= seen_h / category(label).typical_size_m[2] <= 2.5 and np.isfinite(s_top):
                        s_floor = s_top
                ray = _rays(k, np.array([float(np.median(cols[hit]))]), np.array([float(np.median(bottom[hit])) + 0.5]))[0]
                contact = ray * _in_front_of_walls(ray, s_floor, rot, cam, walls)
                # A solid thing reaches down to its contact: the free pixels of its columns
                # between its outline and its box's bottom edge (a bed's white frame the cut
                # left out) are its own, or it would float. Under a table top or a seat is
                # mostly floor: legged things keep their outline (generation adds the legs).
                if box is not None and np.all(np.isfinite(box)) and label not in LEGGED:
                    low = h - 1 - np.argmax(mask[::-1, cols], axis=0)
                    rows = np.arange(h)[:, None]
                    reach = (rows > low[None, :]) & (rows <= min(box[3], h) - 1) & (labels[:, cols] == 0)
                    if reach.any():
                        grown = np.zeros_like(mask)
                        grown[:, cols] = reach
                        labels[grown] = inst
                        mask |= grown
        if contact is None:
            below_r = np.clip(bottom.astype(np.int64) + 3, 0, h - 1)
            zs = depth[below_r, cols]
            ok = (zs > 0) & (zs < max_depth_m) & (labels[below_r, cols] != inst)
            if ok.mean() < 0.3:
                continue
            z = float(np.median(zs[ok]))
            ray = _rays(k, np.array([float(np.median(cols[ok]))]), np.array([float(np.median(bottom[ok]))]))[0]
            contact = ray * _in_front_of_walls(ray, z, rot, cam, walls)
        # (furniture on the floor stands square to the room; a thing on it may stand any way)
        z_face = _face_depth(mask, contact, up_cam, k, wall_normals_cam if square_to_walls and category(label).on_floor else ())
        good = (z_face > 0.2) & (z_face < max_depth_m)
        if good.mean() < 0.5:
            continue
        rr, cc = np.nonzero(mask)
        depth[rr[good], cc[good]] = z_face[good]
        valid[rr[good], cc[good]] = True
        background[rr, cc] = False
        lifted.append(inst)
    return depth.astype(np.float32), valid, background, labels, tuple(sorted(lifted))
