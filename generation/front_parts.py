"""Part trees from the fronts seen in the photo (``PerceivedObject.fronts``): a carcass with one
moving part per door, drawer or flap where it was seen, instead of a category template's layout.

Each front's corners (world frame, on the face the photo showed) are taken into the fitted box's
frame (``box_from_world``; its +X is the face's normal, so the viewer's right is +Y and up is
+Z); its rectangle there is the mean of its left / right corners' y and of its bottom / top
corners' z (the face may be sheared a little), clipped to the box and kept clear of its
neighbours by ``articulation.GAP_M``. Then, with the panels of the label's template
(``articulation._PARAMS``; particleboard cabinet panels for any other label):

* the carcass: back, sides, top and bottom (``articulation._carcass``), no shelves (drawer trays
  run through where shelves would be), its face closed by panels where no front was seen (a
  range's controls above its oven door; a cabinet's door the parse did not find), or open there
  when those panels stand where the camera saw through (``close_face``);
* a door on a revolute joint at its hinge side, swinging outward, 0..1.7 rad
  (``articulation._vertical_door``);
* a drawer on a prismatic joint along +X, its tray as deep as the carcass, travel 0.8 of the
  carcass depth (``articulation._drawer``);
* a flap (oven, dishwasher door) on a revolute joint at its bottom edge, 0..1.5 rad
  (``articulation._bottom_door``).

Damping, friction and effort limits come from each moving part's mass (``assembly``:
``physics.joint_resistance``), as for the templates.
"""

from __future__ import annotations

import numpy as np

from generation.assembly import PartSpec
from scene_builder.frames import transform_points
from scene_builder.model import Front

__all__ = ["MIN_FRONT_M", "front_parts", "front_rectangles", "fronts_clear_of_walls", "seen_rectangles"]

#: A front narrower or lower than this (m) in the box's frame is left out.
MIN_FRONT_M = 0.05
#: A front's normal must be within this angle of the box's +X: on estimated depth a face's
#: refined yaw and the box's (turned to the walls) disagree by 30 degrees and more
#: (sunrgbd_total3d_demo_5's night stand: 32); a side face is 90 off.
MAX_FACE_ANGLE_DEG = 45.0
#: Moving parts keep this far in front of the walls beside them (fronts_clear_of_walls).
WALL_CLEARANCE_M = 0.005
#: Face panels (front_parts' ``close_face``) reach this far into the carcass panels around them.
FACE_PANEL_OVERLAP_M = 5e-4


def front_rectangles(fronts: tuple[Front, ...], box_from_world: np.ndarray, size_m) -> list[tuple[str, str, float, float, float, float]]:
    """[(kind, hinge, y0, y1, z0, z1)] of ``fronts`` in the box frame of a box of ``size_m`` (D, W,
    H): y in [-W/2, W/2], z in [0, H]; fronts facing away from the box's +X by more than
    MAX_FACE_ANGLE_DEG or smaller than MIN_FRONT_M are left out; overlaps are split."""
    from generation.articulation import GAP_M

    d, w, h = (float(v) for v in size_m)
    out = []
    for f in fronts:
        c = transform_points(box_from_world, f.corners_world_m)  # bl, br, tr, tl
        normal = np.cross(c[1] - c[0], c[3] - c[0])
        n = float(np.linalg.norm(normal))
        if n <= 0 or normal[0] / n < np.cos(np.radians(MAX_FACE_ANGLE_DEG)):
            continue
        y0, y1 = 0.5 * (c[0, 1] + c[3, 1]), 0.5 * (c[1, 1] + c[2, 1])
        z0, z1 = 0.5 * (c[0, 2] + c[1, 2]), 0.5 * (c[2, 2] + c[3, 2])
        y0, y1 = max(y0, -w / 2), min(y1, w / 2)
        z0, z1 = max(z0, 0.0), min(z1, h)
        if y1 - y0 < MIN_FRONT_M or z1 - z0 < MIN_FRONT_M:
            continue
        out.append([f.kind, f.hinge, y0, y1, z0, z1])
    # neighbours that overlap (a front's edge a pixel over the next one's) meet halfway
    for i in range(len(out)):
        for j in range(i + 1, len(out)):
            a, b = out[i], out[j]
            oy = min(a[3], b[3]) - max(a[2], b[2])
            oz = min(a[5], b[5]) - max(a[4], b[4])
            if oy <= -GAP_M or oz <= -GAP_M:
                continue
            if oy < oz:  # side by side: split in y
                lo, hi = (a, b) if a[2] < b[2] else (b, a)
                mid = 0.5 * (lo[3] + hi[2])
                lo[3], hi[2] = mid - GAP_M / 2, mid + GAP_M / 2
            else:  # one above the other: split in z
                lo, hi = (a, b) if a[4] < b[4] else (b, a)
                mid = 0.5 * (lo[5] + hi[4])
                lo[5], hi[4] = mid - GAP_M / 2, mid + GAP_M / 2
    return [tuple(r) for r in out if r[3] - r[2] >= MIN_FRONT_M and r[5] - r[4] >= MIN_FRONT_M]


def fronts_clear_of_walls(rects: list[tuple[str, str, float, float, float, float]], world_from_box: np.ndarray, size_m, walls, clearance_m: float = WALL_CLEARANCE_M) -> list[tuple[str, str, float, float, float, float]]:
    """``rects`` (:func:`front_rectangles`) narrowed so that each moving part, which spans the
    box's whole depth (a drawer's tray), keeps ``clearance_m`` in front of every wall beside it
    (a plane of ``walls`` across the box's width: its normal within 60 degrees of the box's y
    axis). A run fitted into a corner reaches a few millimetres into the side wall, and a drawer
    pressed against the wall by that overlap does not slide (coco128_000000000164's built-in
    drawer opened 1 %). Fronts left narrower than MIN_FRONT_M are dropped; the carcass, welded
    to the room with the wall, is not changed."""
    d = float(size_m[0])
    rot, t = world_from_box[:3, :3], world_from_box[:3, 3]
    out = []
    for kind, hinge, y0, y1, z0, z1 in rects:
        for wall in walls:
            n = rot.T @ wall.normal  # the wall's normal in the box frame
            if abs(n[1]) < 0.5:
                continue
            c = float(wall.normal @ t + wall.offset_m)  # signed distance of the box origin
            # distance(p) = n . p + c >= clearance at the rectangle's corners, x = +-d/2, z = z0, z1
            rest = max(-(n[0] * x + n[2] * z) for x in (-d / 2, d / 2) for z in (z0, z1))
            bound = (clearance_m - c + rest) / n[1]
            if n[1] > 0:
                y0 = max(y0, bound)
            else:
                y1 = min(y1, bound)
        if y1 - y0 >= MIN_FRONT_M:
            out.append((kind, hinge, y0, y1, z0, z1))
    return out


def seen_rectangles(fronts: tuple[Front, ...], world_from_box: np.ndarray, size_m, walls) -> list[tuple[str, str, float, float, float, float]]:
    """``fronts`` as rectangles of a box (:func:`front_rectangles`) at ``world_from_box`` of
    ``size_m``, clear of the ``walls`` beside it (:func:`fronts_clear_of_walls`)."""
    return fronts_clear_of_walls(front_rectangles(fronts, np.linalg.inv(world_from_box), size_m), world_from_box, size_m, walls)


def front_parts(label: str, size_m, rects: list[tuple[str, str, float, float, float, float]], rgba=None, close_face: bool = True) -> list[PartSpec]:
    """Part specifications of a carcass of ``size_m`` = (D, W, H) with a moving part per front
    rectangle of :func:`front_rectangles` (names ``door_K``, ``drawer_K``, ``flap_K`` left to
    right, top to bottom). The parts fill x in [-D/2, D/2] as the templates do. With
    ``close_face``, panels close the carcass's face where no front lies (:func:`_face_panels`):
    a range's control panel above its oven door, a cabinet's front where a door was not found;
    else the face is open there."""
    from generation.articulation import _PARAMS, GAP_M, _bottom_door, _carcass, _drawer, _mat, _vertical_door
    from generation.assembly import ConvexSolids

    p = _PARAMS.get(label, _PARAMS["cabinet"])
    d, w, h = (float(v) for v in size_m)
    t = min(p.panel_m, 0.1 * min(d, w, h))
    td = min(p.door_m, 0.15 * d)
    hp = min(p.handle_m, 0.1 * d)
    x_front = d / 2.0 - hp - GAP_M
    x_door_back = x_front - td
    x_body_front = x_door_back - GAP_M
    body_depth = x_body_front + d / 2.0
    mat_body = _mat(p, rgba, p.panel_density_scale)
    mat_front = _mat(p, rgba)
    g = GAP_M / 2
    panels = _face_panels(rects, w, h, t, g, x_body_front - t, x_body_front) if close_face else []
    body = PartSpec("body", None, ConvexSolids(tuple(_carcass(-d / 2.0, x_body_front, w, h, t)) + tuple(panels)), mat_body,
                    affordance_rank=6, affordance="place objects on top", description=f"{label} carcass")
    parts = [body]
    order = sorted(rects, key=lambda r: (round(-r[5], 2), r[2]))  # top to bottom, left to right
    counts: dict[str, int] = {}
    for kind, hinge, y0, y1, z0, z1 in order:
        counts[kind] = counts.get(kind, 0) + 1
        name = f"{kind}_{counts[kind]}"
        y0, y1, z0, z1 = y0 + g, y1 - g, z0 + g, z1 - g
        if kind == "door":
            parts += _vertical_door(name, "body", x_door_back, x_front, y0, y1, z0, z1, hinge == "left", mat_front, p, rgba)
        elif kind == "drawer":
            parts += _drawer(name, "body", -d / 2.0 + t, x_front, y0, y1, z0, z1, t, h - t, body_depth, mat_front, p, rgba)
        else:
            parts += _bottom_door(name, "body", x_door_back, x_front, y0, y1, z0, z1, mat_front, p, rgba)
    return parts


def _face_panels(rects, w: float, h: float, t: float, g: float, x0: float, x1: float) -> list:
    """Box solids (x in [x0, x1]) closing a carcass's face between its sides, top and bottom where
    no front of ``rects`` ((kind, hinge, y0, y1, z0, z1), each grown by the gap ``g`` the fronts
    keep) lies. Row by row between the fronts' edges, free cells side by side make one solid; the
    solids reach FACE_PANEL_OVERLAP_M into the panels around them (touching faces make
    non-manifold unions)."""
    from generation.assembly import box_solid

    e = FACE_PANEL_OVERLAP_M
    ylo, yhi, zlo, zhi = -w / 2 + t - e, w / 2 - t + e, t - e, h - t + e
    if yhi - ylo <= 2 * g or zhi - zlo <= 2 * g:
        return []
    grown = [(y0 - g, y1 + g, z0 - g, z1 + g) for _, _, y0, y1, z0, z1 in rects]
    ys = sorted({ylo, yhi, *(float(np.clip(v, ylo, yhi)) for r in grown for v in r[:2])})
    zs = sorted({zlo, zhi, *(float(np.clip(v, zlo, zhi)) for r in grown for v in r[2:])})
    out = []
    for za, zb in zip(zs, zs[1:]):
        if zb - za <= 1e-6:
            continue
        zc, run = 0.5 * (za + zb), None
        for ya, yb in zip(ys, ys[1:]):
            if yb - ya <= 1e-6:
                continue
            yc = 0.5 * (ya + yb)
            if not any(r[0] <= yc <= r[1] and r[2] <= zc <= r[3] for r in grown):
                run = (ya, yb) if run is None else (run[0], yb)
                continue
            if run is not None:
                out.append(box_solid([x0, run[0], za], [x1, run[1], zb]))
                run = None
        if run is not None:
            out.append(box_solid([x0, run[0], za], [x1, run[1], zb]))
    return out
