"""Shape priors of rigid categories, fitted to the measured extents (all three of them).

Each builder takes the box size (D, W, H) = (x depth, y width, z height) of the asset frame
(+X front, origin at the bottom centre) and returns part specifications for
:func:`generation.assembly.assemble_asset`. Box-built furniture is a union of convex boxes (the
boxes are the collision pieces, no decomposition needed); bottles, mugs and bowls are surfaces
of revolution scaled to the measured footprint (elliptical when D != W).

Solids that must join into one part overlap by ``_E`` (0.5 mm): solids that only touch make
non-manifold unions.
"""

from __future__ import annotations

import numpy as np

from generation.assembly import ConvexSolids, JointSpec, PartSpec, box_solid
from generation.proportions import TABLE_LABELS, turned_box
from scene_builder.model import JointType, TriangleMesh

__all__ = ["PRIOR_LABELS", "prior_parts", "shelf_boards"]

_E = 5e-4


def _clip(v: float, lo: float, hi: float) -> float:
    return float(min(max(v, lo), hi))


def _legs(d: float, w: float, z_top: float, side: float, inset: float) -> list[TriangleMesh]:
    out = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            cx = sx * (d / 2 - inset - side / 2)
            cy = sy * (w / 2 - inset - side / 2)
            out.append(box_solid([cx - side / 2, cy - side / 2, 0.0], [cx + side / 2, cy + side / 2, z_top]))
    return out


def table_legs(lo_xy, hi_xy, h, inset=None) -> list[TriangleMesh]:
    """The four legs of a table prior whose top spans the plan rectangle ``lo_xy``..``hi_xy`` at
    height h, ``inset`` (m) from its top's edges (None: the category constant)."""
    lo, hi = np.asarray(lo_xy, dtype=np.float64), np.asarray(hi_xy, dtype=np.float64)
    d, w = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    top_t = _clip(0.05 * h, 0.015, 0.05)
    leg = _clip(0.06 * min(d, w), 0.025, 0.08)
    if inset is None:
        inset = _clip(0.03 * min(d, w), 0.0, 0.05)
    shift = np.r_[0.5 * (lo + hi), 0.0]
    return [TriangleMesh(m.vertices_m + shift, m.faces) for m in _legs(d, w, h - top_t + _E, leg, min(inset, max(0.0, min(d, w) / 2 - leg)))]


def _table(d, w, h, material, rgba, label, proportions=None):
    """A top slab on four legs; with ``proportions`` (:mod:`generation.proportions`) its top at
    the height and over the plan seen, its legs at the inset fitted to what was seen."""
    inset, lo, hi = None, np.array([-d / 2, -w / 2]), np.array([d / 2, w / 2])
    if proportions is not None:
        h, inset = proportions.top_m, proportions.leg_inset_m
        lo, hi = proportions.top_plan((d, w, h))
    top_t = _clip(0.05 * h, 0.015, 0.05)
    solids = [box_solid([lo[0], lo[1], h - top_t], [hi[0], hi[1], h])]
    solids += table_legs(lo, hi, h, inset)
    return [PartSpec("body", None, ConvexSolids(tuple(solids)), material, affordance_rank=3,
                     affordance="place objects on top", description=f"{label}: top slab on four legs", rgba=rgba)]


def _chair(d, w, h, material, rgba, label):
    seat_z = _clip(0.5 * h, 0.05, 0.6) if label == "chair" else h
    seat_t = _clip(0.05 * seat_z, 0.015, 0.05)
    leg = _clip(0.07 * min(d, w), 0.02, 0.05)
    solids = [box_solid([-d / 2, -w / 2, seat_z - seat_t], [d / 2, w / 2, seat_z])]
    solids += _legs(d, w, seat_z - seat_t + _E, leg, 0.0)
    if label == "chair" and h - seat_z > 0.05:
        back_t = _clip(0.08 * d, 0.02, 0.06)
        solids.append(box_solid([-d / 2, -w / 2, seat_z - _E], [-d / 2 + back_t, w / 2, h]))
    what = "seat on four legs with a backrest" if label == "chair" else "seat on four legs"
    return [PartSpec("body", None, ConvexSolids(tuple(solids)), material, affordance_rank=2, affordance="sit",
                     description=f"{label}: {what}", rgba=rgba)]


def _shelf_thickness(d, w):
    return _clip(0.05 * min(d, w), 0.008, 0.018)


def _shelf(d, w, h, material, rgba, label, max_pieces: int = 12, boards=None):
    """Side panels, bottom, top and back, and shelf boards: at ``boards`` = ((top height, y from,
    y to, front x), ...) where things were seen resting (:func:`shelf_boards`), else evenly spaced (about
    0.35 m apart)."""
    t = _shelf_thickness(d, w)
    back = _clip(0.02 * d, 0.004, 0.008)
    solids = [
        box_solid([-d / 2, -w / 2, 0.0], [d / 2, -w / 2 + t, h]),
        box_solid([-d / 2, w / 2 - t, 0.0], [d / 2, w / 2, h]),
        box_solid([-d / 2, -w / 2, 0.0], [d / 2, w / 2, t]),
        box_solid([-d / 2, -w / 2, h - t], [d / 2, w / 2, h]),
        box_solid([-d / 2, -w / 2, 0.0], [-d / 2 + back, w / 2, h]),
    ]
    if boards is None:  # evenly spaced, in the frame's part
        n = int(np.clip(round(h / 0.35) - 1, 0, max_pieces - len(solids)))
        for i in range(n):
            z = h * (i + 1) / (n + 1)
            solids.append(box_solid([-d / 2 + back - _E, -w / 2 + t - _E, z - t / 2], [d / 2, w / 2 - t + _E, z + t / 2]))
        what = f"frame with {n} shelves"
    else:
        what = f"frame with {len(boards)} shelf boards where things were seen resting"
    parts = [PartSpec("body", None, ConvexSolids(tuple(solids)), material, affordance_rank=3,
                      affordance="place objects on shelves", description=f"{label}: {what}", rgba=rgba)]
    # Boards where things were seen are welded parts of at most max_pieces boxes each: the
    # collision pieces of one part are capped, and merging boxes of different heights would fill
    # the space between them.
    for k in range(0, len(boards or ()), max_pieces):
        chunk = boards[k:k + max_pieces]
        z0 = min(b[0] for b in chunk) - t
        board_solids = tuple(box_solid([-d / 2 + back - _E, y0, z - t], [x1, y1, z]) for z, y0, y1, x1 in chunk)
        parts.append(PartSpec(f"boards_{k // max_pieces + 1}", "body", ConvexSolids(board_solids), material,
                              JointSpec(JointType.FIXED, (1.0, 0.0, 0.0), (0.0, 0.0, z0)), affordance_rank=3,
                              affordance="place objects on shelves", description=f"{label}: shelf boards", rgba=rgba))
    return parts


#: Things whose bottoms lie within this height of the lowest of them, side by side within
#: BOARD_GAP_M, rest on one board.
BOARD_MERGE_M = 0.08
BOARD_GAP_M = 0.25
#: A board reaches this far past the things on it (within the frame).
BOARD_MARGIN_M = 0.05


def shelf_boards(contents, size_m, shelf_points_m=None) -> tuple[tuple[float, float, float, float], ...]:
    """Shelf boards under what a shelf holds: ``contents`` = (bottom, top, y from, y to, x front) of each
    thing seen inside the shelf's box (box frame, metres), ``size_m`` = (D, W, H),
    ``shelf_points_m``: the shelf's own observed points (box frame). Returns (top height, y from,
    y to, front x) of each board: one under each row of things side by side whose bottoms are
    within BOARD_MERGE_M, its top at the lowest bottom, spanning the row plus BOARD_MARGIN_M,
    from the back to the shelf's front seen there (the 98th percentile of its points' x around
    the board, never behind what it holds; the box's front without points); none where the
    bottom panel holds them (within 3 cm of it) and none that would cut through a thing the
    camera saw."""
    d, w, h = (float(v) for v in size_m)
    t = _shelf_thickness(d, w)
    inner = (-w / 2 + t, w / 2 - t)
    rows: list[list[float]] = []  # [z, y0, y1, x front of what is on it]
    for z, _, y0, y1, x1 in sorted(tuple(float(v) for v in c) for c in contents):
        if z < t + 0.03 or z > h - t:
            continue
        for row in rows:
            if z - row[0] <= BOARD_MERGE_M and y0 - row[2] <= BOARD_GAP_M and row[1] - y1 <= BOARD_GAP_M:
                row[1], row[2], row[3] = min(row[1], y0), max(row[2], y1), max(row[3], x1)
                break
        else:
            rows.append([z, y0, y1, x1])
    pts = None if shelf_points_m is None else np.asarray(shelf_points_m, dtype=np.float64)
    boards = []
    for z, y0, y1, x1 in rows:
        y0, y1 = max(inner[0], y0 - BOARD_MARGIN_M), min(inner[1], y1 + BOARD_MARGIN_M)
        front = d / 2
        if pts is not None:
            near = (pts[:, 1] >= y0) & (pts[:, 1] <= y1) & (np.abs(pts[:, 2] - z) <= 0.1)
            if np.count_nonzero(near) >= 20:
                front = float(np.clip(max(np.percentile(pts[near, 0], 98), x1), -d / 2 + 0.05, d / 2))
        cuts = any(b + 0.01 < z and z - t < e - 0.01 and c < y1 and y0 < f for b, e, c, f, _ in contents)
        if y1 - y0 > 0.02 and not cuts:
            boards.append((z, y0, y1, front))
    return tuple(boards)


def _sofa(d, w, h, material, rgba, label, proportions=None):
    """A bed (mattress base, headboard) or a sofa (seat base, backrest, arms; its category's
    constants). A bed's ``proportions`` (:class:`generation.proportions.Proportions`): its
    mattress top and its headboard's side as measured (no headboard where none was seen: a
    block of the box's height); None: the constants, the headboard on -x."""
    if label == "bed":
        side = "-x" if proportions is None or proportions.back_side is None else proportions.back_side
        dd, ww = (d, w) if side in ("-x", "+x") else (w, d)  # length and width with the head on -x

        def box(lo, hi):
            return box_solid(*turned_box(side, lo, hi))

        if proportions is None:
            base_h = 0.75 * h if h > 0.4 else h
        else:
            base_h = proportions.top_m if proportions.back_side is not None else h
        solids = [box([-dd / 2, -ww / 2, 0.0], [dd / 2, ww / 2, base_h])]
        if base_h < h:
            head = _clip(0.04 * dd, 0.03, 0.08)
            solids.append(box([-dd / 2, -ww / 2, 0.0], [-dd / 2 + head, ww / 2, h]))
        return [PartSpec("body", None, ConvexSolids(tuple(solids)), material, affordance_rank=2, affordance="lie down",
                         description="bed: mattress base with a headboard", rgba=rgba)]
    seat_h = 0.5 * h
    back_d = 0.25 * d
    arm_w = _clip(0.12 * w, 0.05, 0.25) if w > 4 * 0.12 * d else 0.0
    solids = [
        box_solid([-d / 2, -w / 2, 0.0], [d / 2, w / 2, seat_h]),
        box_solid([-d / 2, -w / 2, seat_h - _E], [-d / 2 + back_d, w / 2, h]),
    ]
    if arm_w > 0:
        arm_top = seat_h + 0.4 * (h - seat_h)
        solids.append(box_solid([-d / 2 + back_d - _E, -w / 2, seat_h - _E], [d / 2, -w / 2 + arm_w, arm_top]))
        solids.append(box_solid([-d / 2 + back_d - _E, w / 2 - arm_w, seat_h - _E], [d / 2, w / 2, arm_top]))
    return [PartSpec("body", None, ConvexSolids(tuple(solids)), material, affordance_rank=2, affordance="sit",
                     description="sofa: seat base, backrest and arms", rgba=rgba)]


def _counter(d, w, h, material, rgba, label):
    top_t = _clip(0.035 * h, 0.02, 0.04)
    body = PartSpec("body", None, ConvexSolids((box_solid([-d / 2, -w / 2, 0.0], [d / 2 - 0.02, w / 2, h - top_t]),)),
                    "particleboard", affordance_rank=6, affordance="open below", description=f"{label}: cabinet body",
                    shell_thickness_m=0.018, rgba=rgba)
    top_mat = "stone" if label == "counter" else "ceramic"
    top = PartSpec("top", "body", ConvexSolids((box_solid([-d / 2, -w / 2, h - top_t], [d / 2, w / 2, h]),)), top_mat,
                   JointSpec(JointType.FIXED, (1.0, 0.0, 0.0), (0.0, 0.0, h - top_t)), affordance_rank=2,
                   affordance="place objects on top" if label == "counter" else "wash hands",
                   description=f"{label}: {top_mat} top", rgba=rgba)
    return [body, top]


def _box(d, w, h, material, rgba, label, shell):
    return [PartSpec("body", None, ConvexSolids((box_solid([-d / 2, -w / 2, 0.0], [d / 2, w / 2, h]),)), material,
                     affordance_rank=3, affordance="pick up" if label in ("box", "book") else "look at",
                     description=f"{label}: box", shell_thickness_m=shell, rgba=rgba)]


def _bin(d, w, h, material, rgba, label):
    t = _clip(0.02 * min(d, w), 0.002, 0.005)
    solids = [
        box_solid([-d / 2, -w / 2, 0.0], [d / 2, w / 2, t]),
        box_solid([-d / 2, -w / 2, 0.0], [-d / 2 + t, w / 2, h]),
        box_solid([d / 2 - t, -w / 2, 0.0], [d / 2, w / 2, h]),
        box_solid([-d / 2, -w / 2, 0.0], [d / 2, -w / 2 + t, h]),
        box_solid([-d / 2, w / 2 - t, 0.0], [d / 2, w / 2, h]),
    ]
    return [PartSpec("body", None, ConvexSolids(tuple(solids)), material, affordance_rank=2,
                     affordance="throw things in", description="bin: open-top container", rgba=rgba)]


def _screen(d, w, h, material, rgba, label):
    screen_d = min(d, 0.06 if label == "tv" else 0.05)
    if d < 0.1 or h < 0.15:
        solids = [box_solid([-screen_d / 2, -w / 2, 0.0], [screen_d / 2, w / 2, h])]
        what = "flat panel"
    else:
        base_h = _clip(0.03 * h, 0.01, 0.02)
        neck_z = 0.25 * h if label == "monitor" else 0.12 * h
        neck = _clip(0.08 * w, 0.03, 0.08)
        solids = [
            box_solid([-d / 2, -0.3 * w / 2, 0.0], [d / 2, 0.3 * w / 2, base_h]),
            box_solid([-d / 2 + 0.01, -neck / 2, base_h - _E], [-d / 2 + 0.01 + screen_d / 2, neck / 2, neck_z + _E]),
            box_solid([-d / 2, -w / 2, neck_z], [-d / 2 + screen_d, w / 2, h]),
        ]
        what = "panel on a stand"
    return [PartSpec("body", None, ConvexSolids(tuple(solids)), material, affordance_rank=4, affordance="watch",
                     description=f"{label}: {what}", rgba=rgba)]


def _revolved(profile_rz: np.ndarray, d: float, w: float, h: float, sections: int = 32):
    """Surface of revolution of a closed (r, z) profile in [0, 1] x [0, 1] (starting and ending
    on the axis), scaled to the footprint (d, w) and height h."""
    import trimesh

    m = trimesh.creation.revolve(np.asarray(profile_rz, dtype=np.float64), sections=sections)
    if float(m.volume) < 0:
        m.invert()
    m.apply_scale([d / 2.0, w / 2.0, h])
    return m


def _ring_points(profile_rz: np.ndarray, angles: np.ndarray, d: float, w: float, h: float) -> np.ndarray:
    """(len(profile) * len(angles), 3) points of (r, z) profile points swept to ``angles``."""
    r, z = profile_rz[:, 0][:, None], profile_rz[:, 1][:, None]
    pts = np.stack([r * np.cos(angles) * d / 2, r * np.sin(angles) * w / 2, np.broadcast_to(z * h, (len(z), len(angles)))], -1)
    return pts.reshape(-1, 3)


def _vessel_pieces(outer: np.ndarray, inner: np.ndarray, bottom: float, d, w, h, sectors: int) -> list[TriangleMesh]:
    """Convex pieces tiling an open vessel: the bottom disc and ``sectors`` wall sectors (each the
    hull of the wall's outer and inner profile over its angle span, overlapping its neighbours
    by 1 degree so the pieces join). CoACD on thin-walled vessels takes 8-11 s for 12 pieces;
    the vessel's own structure gives convex pieces directly."""
    import trimesh

    from generation.meshing import to_model_mesh

    ring = np.linspace(0, 2 * np.pi, 33)[:-1]
    r0 = float(np.interp(bottom, outer[:, 1], outer[:, 0]))
    disc = np.vstack([_ring_points(np.array([[outer[0, 0], 0.0]]), ring, d, w, h),
                      _ring_points(np.array([[r0, bottom]]), ring, d, w, h)])
    pieces = [to_model_mesh(trimesh.convex.convex_hull(disc))]
    step = 2 * np.pi / sectors
    pad = np.radians(1.0)
    wall = np.vstack([outer[outer[:, 1] >= 0.5 * bottom], inner])
    for k in range(sectors):
        ang = np.linspace(k * step - pad, (k + 1) * step + pad, 4)
        pieces.append(to_model_mesh(trimesh.convex.convex_hull(_ring_points(wall, ang, d, w, h))))
    return pieces


def _vessel(d, w, h, material, rgba, label, shell, max_pieces: int = 12):
    if label == "bottle":
        prof = [[0, 0], [1, 0], [1, 0.62], [0.85, 0.72], [0.4, 0.82], [0.38, 1.0], [0, 1.0]]
        m = _revolved(np.array(prof, dtype=np.float64)[::-1], d, w, h)
        tm = TriangleMesh(np.asarray(m.vertices), np.asarray(m.faces))
        return [PartSpec("body", None, tm, material, affordance_rank=1, affordance="grasp and pour",
                         description="bottle: body, shoulder and neck", shell_thickness_m=shell, rgba=rgba)]
    if label == "mug":
        wall = _clip(0.006 / (0.5 * min(d, w)), 0.05, 0.3)
        bottom = _clip(0.008 / h, 0.03, 0.3)
        outer = np.array([[1.0, 0.0], [1.0, 1.0]])
        inner = np.array([[1 - wall, bottom], [1 - wall, 1.0]])
        what, aff = "mug: cylindrical cup", "grasp and drink"
    else:  # bowl
        wall = _clip(0.005 / (0.5 * min(d, w)), 0.03, 0.3)
        bottom = wall * 0.8 + 0.06
        outer = np.array([[0.55, 0.0], [0.8, 0.25], [0.95, 0.6], [1.0, 1.0]])
        inner = np.array([[0.55 - wall, bottom], [0.8 - wall, 0.3], [0.95 - wall, 0.62], [1 - wall, 1.0]])
        what, aff = "bowl: rounded open vessel", "place food in"
    # closed profile: axis at the bottom, outer wall up, rim, inner wall down, axis at the floor
    profile = np.vstack([[[0.0, 0.0]], outer, inner[::-1], [[0.0, bottom]]])[::-1]
    m = _revolved(profile, d, w, h)
    visual = TriangleMesh(np.asarray(m.vertices), np.asarray(m.faces))
    pieces = _vessel_pieces(outer, inner, bottom, d, w, h, max(3, min(max_pieces, 12) - 1))
    return [PartSpec("body", None, ConvexSolids(tuple(pieces), visual=visual), material, affordance_rank=1,
                     affordance=aff, description=what, shell_thickness_m=shell, rgba=rgba)]


PRIOR_LABELS = (
    "table", "desk", "chair", "stool", "shelf", "sofa", "bed", "counter", "sink",
    "box", "book", "bin", "tv", "monitor", "bottle", "mug", "bowl",
)


def prior_parts(label: str, size_m, material: str, shell_thickness_m: float | None, rgba=None,
                max_pieces: int = 12, boards=None, proportions=None) -> list[PartSpec]:
    """Part specifications of the shape prior of ``label`` fitted to ``size_m`` = (D, W, H).
    ``boards``: a shelf's boards where things were seen resting in it (:func:`shelf_boards`).

    Raises ValueError for a label without a prior (see :data:`PRIOR_LABELS`).
    """
    d, w, h = (float(v) for v in size_m)
    if label in TABLE_LABELS:
        return _table(d, w, h, material, rgba, label, proportions)
    if label in ("chair", "stool"):
        return _chair(d, w, h, material, rgba, label)
    if label == "shelf":
        return _shelf(d, w, h, material, rgba, label, max_pieces, boards)
    if label in ("sofa", "bed"):
        return _sofa(d, w, h, material, rgba, label, proportions)
    if label in ("counter", "sink"):
        return _counter(d, w, h, material, rgba, label)
    if label in ("box", "book"):
        return _box(d, w, h, material, rgba, label, shell_thickness_m)
    if label == "bin":
        return _bin(d, w, h, material, rgba, label)
    if label in ("tv", "monitor"):
        return _screen(d, w, h, material, rgba, label)
    if label in ("bottle", "mug", "bowl"):
        return _vessel(d, w, h, material, rgba, label, shell_thickness_m, max_pieces)
    raise ValueError(f"no shape prior for '{label}'; priors: {', '.join(PRIOR_LABELS)}")
