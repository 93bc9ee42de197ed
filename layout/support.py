"""Support graph: which object rests on which (floor, another object's top face, the static
background seen under it, or a wall for built-in furniture), built bottom-up from geometry, and
the vertical placement that makes each resting contact exact.

An object rests on the highest support found in a band around where it was seen: from
:data:`MAX_DROP_M` below its observed bottom to :data:`SUPPORT_TOL_M` above. Nothing falls
further than that: an object with nothing under it in the band is not dropped to whatever lies
metres below. If the camera could not see under it (hidden behind itself or a nearer object),
it keeps its height and stands on the highest support up to 1 m below; if the camera saw
through the space under it, it hangs, is left where it was seen, unsupported, and the layout
makes it part of the static background (built-in furniture against a wall hangs on the wall
instead)."""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from layout.bodies import Body
from layout.geometry import SupportSurface, clip_convex_polygons, convex_hull_2d, polygon_area
from scene_builder.model import AssetKind, Plane, SupportEdge

FLOOR, WALL, BACKGROUND, UNSUPPORTED = -1, -2, -3, -4
# A top face counts as a support when it lies below the object's bottom + this tolerance
# (observed bottoms sink into supports by depth noise and by completion errors). Not more: an
# object standing on the floor next to a low box must not be lifted onto it.
SUPPORT_TOL_M = 0.05
# Share of the object's footprint that must lie over the face.
MIN_FOOTPRINT_OVERLAP = 0.25
# An object whose bottom was seen (or completed) sunk up to this far into a top face rests on it
# when most of its footprint lies over it (SUNK_FOOTPRINT_OVERLAP): a plant's pot or a lamp's
# base completed a few centimetres into the dresser it stands on (sunrgbd_imvotenet_000003's
# plant sank 5 cm and, with nothing else under it, became background, then the dresser for it).
SINK_INTO_SUPPORT_M = 0.15
SUNK_FOOTPRINT_OVERLAP = 0.6
# ... and a face under that much of its footprint is its support even when it leaves it this
# deep in the rest of the supporter (layout.trim cuts such overlaps apart; layout.trim.MAX_TRIM_M).
SUNK_CLASH_TOL_M = 0.06
# A piece top under more than this share of a body's footprint is one of the steps of a merged
# top it may rest on; the tops within STEP_LEVEL_M of the highest of those make its step.
STEP_OVERLAP = 0.02
STEP_LEVEL_M = 0.005
# ... made into one step when they cover this share of their hull (a top's voxel columns), else
# the one most under it alone.
STEP_MIN_COVER = 0.9
# Faces lower than this are the floor's business.
MIN_SURFACE_HEIGHT_M = 0.02
# Background seen around an object lower than this (a rug, a carpet's pile, depth noise on the
# floor) is the floor: an object within reach of the floor rests on it (on legs when it was seen
# higher), not on a pad over the hidden floor under it, which its neighbours' completions reach
# into (beds of four SUN RGB-D samples became background for that).
FLOOR_LIKE_M = 0.06
# A candidate face is rejected when the object set on it would sink deeper than this into the
# rest of the support (smaller overlaps are left to the horizontal solver).
SUPPORT_CLASH_TOL_M = 0.01
# A soft body rests on a face only when the face has at least this share of its footprint's area
# (a pillow draped over a narrower pillow or a sofa's arm slides off in simulation).
DEFORMABLE_MIN_FACE_AREA = 0.5
# Fixed (built-in) furniture this close to a wall and off the floor hangs on the wall.
WALL_CONTACT_M = 0.05
# Things made to hang on a wall (a wall-mounted television, an over-the-range microwave, a wall
# cabinet or shelf, a clock, a sconce): seen within WALL_MOUNT_REACH_M of a wall with nothing
# under them, they are mounted on it, welded where seen (``ObjectAsset.is_fixed``), not left hanging as
# static background (an over-the-range microwave hangs above the hob). A bottle or a book
# against a wall with nothing under it is not mounted: it stays background, counted.
WALL_MOUNTED = frozenset({"tv", "monitor", "microwave", "cabinet", "shelf", "clock", "lamp"})
# Depth estimated from one photo puts a picture on its wall 13-18 cm in front of it
# (``sunrgbd_imvotenet_000004`` as a plain photo); a television on an arm, a cabinet on rails or a
# sconce stands that far off the wall anyway.
WALL_MOUNT_REACH_M = 0.15
# Of those, the ones mounted even when a support lies far below them (more than their own
# height): not a lamp, which may be a floor lamp standing on a stem the camera did not see.
MOUNTED_ABOVE_SUPPORT = WALL_MOUNTED - {"lamp"}
# A support more than this far below an object's observed bottom is not what it rests on: the
# object would drop further than its observed bottom can be wrong (legs hidden behind a nearer
# object are extended to the floor by generation, ``generation.pose.floor_snap_height_m``).
MAX_DROP_M = 0.15
# A hidden gap under an object up to this share of its own height is its own hidden lower part
# (legs); a larger one is something else's (a static column stands in for it).
HIDDEN_OWN_SHARE = 0.5
# A hidden support is looked for at most this far under an object (a monitor seen at eye level
# with nothing under it is on the wall, not on a hidden 1.7 m column).
HIDDEN_MAX_DROP_M = 1.0
# Furniture that stands on legs or a stem the camera may see past (a desk's top seen over the
# floor between its legs, a chair whose star base is cut from its mask, a floor lamp's pole): seen
# with empty space under it, it stands where seen on collision legs down to the highest support
# up to this far below, instead of hanging as static background.
STANDS_ON_LEGS = frozenset(
    {"chair", "stool", "bench", "table", "desk", "sofa", "bed", "cabinet", "drawer_unit", "shelf", "wardrobe", "lamp", "plant", "tv", "monitor"}
)
LEGS_MAX_DROP_M = 1.5
# Legs longer than this many times the object's narrowest footprint width make a stilt it topples
# from: what is not furniture on legs stands on a static column down to the floor instead.
SLENDER_LEGS = 1.5
# Anything else with its underside hidden stands on legs down to an object's top at most this
# share of its own height below it (its hidden lower part).
HIDDEN_LEGS_SHARE = 1.0
# ... on the floor, not on low clutter seen under it (a box under a desk, the floor's own depth
# noise): background under legs counts from this height up (a counter, a static dresser's top).
LEGS_MIN_BACKGROUND_M = 0.25


# Centre of mass of a rigid object kept this far inside its supporting face: at least
# SUPPORT_INSET_M, and SUPPORT_INSET_FRACTION of the object's narrowest footprint width (a lamp
# whose centre of mass is 1 cm inside a sofa's back edge topples at the first nudge).
SUPPORT_INSET_M = 0.01
SUPPORT_INSET_FRACTION = 0.2


#: Why a body is left where seen when the surface seen under it is there but another body's
#: pieces fill the space under it (its pad would reach into them).
BLOCKED_PAD_REASON = "what is under it is another object's, with no face to rest on"


def support_inset_m(b: Body) -> float:
    """How far inside its supporting face a rigid body's centre of mass is kept (m)."""
    extent = np.ptp(b.footprint_rel_m, axis=0) if len(b.footprint_rel_m) else np.zeros(2)
    return max(SUPPORT_INSET_M, SUPPORT_INSET_FRACTION * float(np.min(extent)))


def _footprint_world(b: Body) -> np.ndarray:
    return b.footprint_rel_m + b.position_m[:2]


def overlap_fraction(foot: np.ndarray, poly: np.ndarray) -> float:
    area = polygon_area(foot)
    if area <= 1e-8:
        # Degenerate footprint (a point or a line): inside or not, by its centroid.
        c = foot.mean(axis=0)
        d = np.roll(poly, -1, axis=0) - poly
        side = d[:, 0] * (c[1] - poly[:, 1]) - d[:, 1] * (c[0] - poly[:, 0])
        return 1.0 if np.all(side >= 0) else 0.0
    return polygon_area(clip_convex_polygons(foot, poly)) / area


def _near_wall(b: Body, walls: tuple[Plane, ...], reach_m: float = WALL_CONTACT_M) -> bool:
    if not walls:
        return False
    v = b.world_vertices()
    return any(float(np.min(w.clearance_m(v))) < reach_m for w in walls)


def _mount(b: Body, where: str) -> None:
    """Weld ``b`` to the room where it was seen (parent WALL): its asset becomes fixed, and
    ``b.mounted`` says the layout fixed it (its completion is still cut at the walls and one
    reaching deep into a wall is still background, like a movable one's)."""
    b.parent, b.mounted = WALL, where
    if not b.fixed:
        b.fixed = True
        b.asset = dataclasses.replace(b.asset, is_fixed=True)


def pad_box(b: Body, height_m: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The pad under body ``b`` resting on the background at ``height_m`` (its whole plan extent,
    ``layout.background.support_pad``): centre (3,), half extents (3,), yaw (rad), at the
    body's current plan position."""
    from layout.background import support_pad

    plan = np.concatenate([p.verts_rel_m[:, :2] for p in b.pieces])
    return support_pad(plan, b.rotation, b.position_m, height_m, b.pad_bottom_m, b.pad_rect_m)


def pad_bounds(centre: np.ndarray, half: np.ndarray, yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """World axis-aligned bounds (lo, hi) of a yawed pad box."""
    ext = np.abs(np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])) @ half[:2]
    return (np.array([centre[0] - ext[0], centre[1] - ext[1], centre[2] - half[2]]),
            np.array([centre[0] + ext[0], centre[1] + ext[1], centre[2] + half[2]]))


def pad_frame(b: Body, height_m: float, box: tuple[np.ndarray, np.ndarray, float] | None = None) -> tuple[np.ndarray, float, float, float, np.ndarray]:
    """The pad under body ``b`` resting on the background at ``height_m``, in ``b``'s yawed axes
    relative to its position: its rectangle (lo_x, lo_y, hi_x, hi_y), its yaw, its height band
    (bottom, top less ``layout.background.CARVE_CLEARANCE_M``) and ``b``'s centre of mass (2,).
    box: :func:`pad_box` of ``b`` at ``height_m`` when the caller has it already."""
    from layout.background import CARVE_CLEARANCE_M

    centre, half, yaw = pad_box(b, height_m) if box is None else box
    c, s = np.cos(yaw), np.sin(yaw)
    to_local = np.array([[c, -s], [s, c]])  # world offsets -> the pad's axes
    mid = (centre[:2] - b.position_m[:2]) @ to_local
    rect = np.concatenate([mid - half[:2], mid + half[:2]])
    return rect, yaw, float(centre[2] - half[2]), float(centre[2] + half[2] - CARVE_CLEARANCE_M), b.com_rel_m[:2] @ to_local


def _clear_pad_rect(b: Body, height_m: float, others: list[Body]) -> np.ndarray | None:
    """The pad under ``b`` at ``height_m`` (its rectangle, :func:`pad_frame`), cut back clear of
    the other bodies' pieces where their plan hulls reach into it with ``b``'s centre of mass
    still held inside (``layout.background.clip_pad``), or None where no cut does: then another
    object fills the space under it, and that object is what it would rest on, not the
    background. A box on a dresser whose pad a neighbour's top corner reaches 2 cm into
    (``sunrgbd_imvotenet_000003``) rests on the rest of it."""
    from layout.background import clip_pad

    box = pad_box(b, height_m)
    rect, yaw, z_lo, z_hi, com = pad_frame(b, height_m, box)
    lo, hi = pad_bounds(*box)
    hi[2] = z_hi
    near = [
        (o.asset.kind is AssetKind.DEFORMABLE, p.verts_rel_m + o.position_m)
        for o in others
        for p, plo, phi in zip(o.pieces, o.piece_lo_rel_m + o.position_m, o.piece_hi_rel_m + o.position_m)
        if np.all(lo < phi) and np.all(hi > plo)
    ]
    if not near:
        return rect
    if clip_pad(rect, yaw, b.position_m, z_lo, z_hi, [v for soft, v in near if soft], np.zeros(2), 0.0, probe=True) is None:
        # A soft neighbour under it is not cut around: it spreads as it settles and tips what
        # stands beside it (sunrgbd_imvotenet_000005's mug by a pillow, toppled in the settle).
        return None
    cut = clip_pad(rect, yaw, b.position_m, z_lo, z_hi, [v for _, v in near], com, support_inset_m(b))
    if cut is not None and b.asset.kind is AssetKind.DEFORMABLE and np.prod(cut[2:] - cut[:2]) < DEFORMABLE_MIN_FACE_AREA * np.prod(rect[2:] - rect[:2]):
        return None  # a soft body keeps as much of its pad as it needs of a face (it drapes off less)
    return cut


def step_face(s: Body, height_rel_m: float, foot: np.ndarray) -> SupportSurface | None:
    """The step of ``s``'s merged top at ``height_rel_m`` that a body with footprint ``foot``
    (world) rests on: the hull of the piece tops at the height of the highest of them under it,
    those under it. A merged top lies at its highest piece's height and spans its lower ones (a
    completed night stand's top steps 0.77-0.82 m): a price card set on it over the lower pieces
    hovered 2.4 cm over what held it, and the pushes kept its centre of mass anywhere in the
    merged hull, past the lower pieces' edge (sunrgbd_imvotenet_000002: it dropped and tipped).
    None when no piece top lies under it."""
    import shapely

    from layout.geometry import MERGE_BAND_M

    under = [
        f for f in s.surfaces[: s.merged_from]
        if height_rel_m - MERGE_BAND_M - 1e-9 <= f.height_rel_m <= height_rel_m + 1e-9
        and overlap_fraction(foot, f.polygon_rel_m + s.position_m[:2]) > STEP_OVERLAP
    ]
    top = max((f.height_rel_m for f in under), default=0.0)
    level = [f.polygon_rel_m for f in under if f.height_rel_m >= top - STEP_LEVEL_M and len(f.polygon_rel_m) >= 3]
    if not level:
        return None
    hull = convex_hull_2d(np.concatenate(level))
    if len(hull) < 3:
        return None
    if shapely.union_all([shapely.Polygon(q) for q in level]).area < STEP_MIN_COVER * polygon_area(hull):
        # Tops apart (two boards of a shelf with a gap between them): the hull would hold it over
        # the gap; it rests on the one most under it.
        hull = max(level, key=lambda q: overlap_fraction(foot - s.position_m[:2], q))
    return SupportSurface(float(top), hull)


def build_support(
    bodies: list[Body],
    walls: tuple[Plane, ...],
    clash: Callable[[int, int, float], float] | None = None,
    background: Callable[[np.ndarray, float, float], float | None] | None = None,
    max_lower_m: float = 0.02,
    hidden: Callable[[np.ndarray, float], bool] | None = None,
) -> tuple[list[SupportEdge], list[int]]:
    """Assign each body its support and set its height so that it rests exactly on it.

    Bodies are processed bottom-up (by initial bottom height, then name), and a body can only rest
    on a body processed before it, so the graph has no cycles. The candidates lie between
    MAX_DROP_M below the body's bottom and SUPPORT_TOL_M above it: the top faces of earlier bodies
    under at least 25 % of its footprint (rigid bodies never rest on soft ones), the background
    surface seen around its footprint (``background(footprint_world (K, 2), low_m, high_m)``
    gives its height or None; ``layout.background.BackgroundSupport.height_under``), and the
    floor.
    With none, fixed furniture off the floor and against a wall hangs on the wall; anything else
    is left where it was seen with ``parent = UNSUPPORTED`` (the layout turns it into
    background). Updates ``position_m[2]``, ``parent``, ``support_surface`` and ``children`` in
    place. Returns the edges (in processing order) and the processing order.
    Among the candidates the one nearest to the observed bottom wins (ties: an object's face,
    then the background, then the floor). A rigid body more than ``max_lower_m`` above its
    support keeps its height (``legs_m`` is set: it will stand on collision legs).
    ``hidden(footprint_world (K, 2), bottom_m)``: whether the space under the body was hidden from
    the camera (``layout.background.HiddenBelow``); a rigid, free body with no candidate in the
    band whose underside was hidden takes the highest candidate up to HIDDEN_MAX_DROP_M below, on legs
    (``hidden_support`` is set), or, more than MAX_DROP_M above the floor or the background,
    rests on the background on a pad column from there (``pad_bottom_m`` is set).

    ``clash(child, support, z)``: penetration depth (m) of the child placed at height z against the
    support. A face that the child, set on it, would sink into the rest of the support (the top
    of a lower convex piece buried inside the object) is skipped for the next one.
    """
    order = sorted(range(len(bodies)), key=lambda i: (bodies[i].bottom_m, bodies[i].name))
    edges: list[SupportEdge] = []
    placed: list[int] = []
    for b in bodies:
        b.parent, b.support_surface, b.children, b.pad_bottom_m, b.pad_rect_m, b.step_face = FLOOR, -1, [], None, None, None
    # Plan boxes of the bodies placed so far (vectorised prefilter of candidate supports).
    placed_lo = np.zeros((len(bodies), 2))
    placed_hi = np.zeros((len(bodies), 2))
    for i in order:
        b = bodies[i]
        bottom = b.bottom_m
        tol = SUPPORT_TOL_M
        foot = _footprint_world(b)
        soft = b.asset.kind is AssetKind.DEFORMABLE
        min_face_area = DEFORMABLE_MIN_FACE_AREA * polygon_area(foot) if soft else 0.0
        lo_xy = foot.min(axis=0)
        hi_xy = foot.max(axis=0)
        pad_blocked = False  # the background seen under it was found, but another body fills the pad
        pad_rects: dict[float, np.ndarray] = {}  # background height -> the pad's rectangle there
        steps: dict[tuple[int, int], SupportSurface] = {}  # (body, merged top) -> the step under it

        def search(drop_m: float, objects: bool = True, min_background_m: float = 0.0) -> list[tuple[float, int, float, int, int]]:
            nonlocal pad_blocked
            candidates: list[tuple[float, float, int, int]] = []  # (height, overlap, -body, surface)
            n_placed = len(placed)
            near = np.nonzero(
                np.all(placed_lo[:n_placed] <= hi_xy, axis=1) & np.all(placed_hi[:n_placed] >= lo_xy, axis=1)
            )[0]
            for j in (placed[k] for k in near if objects):
                s = bodies[j]
                if not soft and s.asset.kind is AssetKind.DEFORMABLE:
                    # A soft body sags under a rigid load and tips it (a chair on a cushion tilted 11 deg
                    # in 3 s on open3d_TUM): rigid objects rest on the next support below instead.
                    continue
                for k, surf in enumerate(s.surfaces):
                    h = float(s.position_m[2] + surf.height_rel_m)
                    if h < max(MIN_SURFACE_HEIGHT_M, bottom - drop_m) or h > bottom + SINK_INTO_SUPPORT_M or polygon_area(surf.polygon_rel_m) < min_face_area:
                        continue
                    frac = overlap_fraction(foot, surf.polygon_rel_m + s.position_m[:2])
                    if frac < (MIN_FOOTPRINT_OVERLAP if h <= bottom + tol else SUNK_FOOTPRINT_OVERLAP):
                        continue
                    if k >= s.merged_from:
                        step = step_face(s, surf.height_rel_m, foot)
                        if step is not None:
                            steps[(j, k)] = step
                            h = float(s.position_m[2] + step.height_rel_m)
                    candidates.append((h, frac, -j, k))
            # The support nearest to the observed bottom wins (ties: an object's face, then the
            # background, then the floor): the object moves as little as it can.
            options: list[tuple[float, int, float, int, int]] = []  # (|gap|, rank, h, parent, surface)
            for h, frac, neg_j, k in sorted(candidates, reverse=True):
                z = float(b.position_m[2] + h - bottom)
                # A face mostly under it may leave a shallow overlap with the rest of the
                # support (a completed dresser top stepping a few centimetres, the side of a
                # mirror behind a plant): the layout trims that; a deeper one means the face is
                # buried inside the object.
                tol_clash = SUNK_CLASH_TOL_M if frac >= SUNK_FOOTPRINT_OVERLAP else SUPPORT_CLASH_TOL_M
                if clash is None or clash(i, -neg_j, z) <= tol_clash:
                    options.append((abs(h - bottom), 0, h, -neg_j, k))
                    break
            if background is not None:
                h_bg = background(foot, max(MIN_SURFACE_HEIGHT_M, bottom - drop_m), bottom + tol)
                if h_bg is not None and h_bg < max(FLOOR_LIKE_M, min_background_m) and bottom <= drop_m:
                    h_bg = None  # the floor (seen with a rug or noise on it) is within reach
                rect = None if h_bg is None else _clear_pad_rect(b, h_bg, [bodies[k] for k in placed])
                if rect is not None:
                    options.append((abs(h_bg - bottom), 1, h_bg, BACKGROUND, -1))
                    pad_rects[h_bg] = rect
                elif h_bg is not None:
                    pad_blocked = True
            if bottom <= drop_m:
                options.append((abs(bottom), 2, 0.0, FLOOR, -1))
            return options

        options = search(MAX_DROP_M)
        hidden_under = False
        seen_under = False
        if not options and hidden is not None and not soft and not b.fixed:
            seen_under = not hidden(foot, bottom)
        if not options and hidden is not None and not soft and not b.fixed and not seen_under:
            # Nothing seen within reach under it, and the camera could not see under it either:
            # whatever holds it up is hidden (a nightstand behind the bed, a bed's own frame).
            # It keeps its height and stands on legs down to the highest support below.
            # (Not onto another object: a hidden support under it would be seen beside it.)
            options = search(HIDDEN_MAX_DROP_M, objects=False)
            hidden_under = bool(options)
            if not options:
                # Nor the floor or background within reach: another object's top under it, hidden
                # (a box on a shelf unit whose front hides the box's lower half). It stands on
                # legs down to it when the gap is no more than its own hidden lower part could be.
                options = [o for o in search(HIDDEN_MAX_DROP_M) if o[3] >= 0 and bottom - o[2] <= max(MAX_DROP_M, HIDDEN_LEGS_SHARE * b.height_m)]
        if not options and not soft and not b.fixed and hidden is not None and b.asset.label in STANDS_ON_LEGS:
            # Its legs (or stem, or base) were not seen, or were hidden: legs down to what it
            # stands on.
            options = search(LEGS_MAX_DROP_M, min_background_m=LEGS_MIN_BACKGROUND_M)
        mountable = b.asset.label in WALL_MOUNTED and _near_wall(b, walls, WALL_MOUNT_REACH_M)
        if options and mountable and b.asset.label in MOUNTED_ABOVE_SUPPORT and not b.fixed and min(options)[0] > max(MAX_DROP_M, b.height_m):
            # Made to hang on a wall, seen against one more than its own height above what is
            # under it (a picture read as a television 68 cm above a bed's pillows): it hangs
            # there, mounted, rather than standing on legs down to the bed.
            options = []
        if options:
            _, _, h, j, k = min(options)
            narrow = float(np.min(np.ptp(foot, axis=0))) if len(foot) else 0.0
            slender = b.asset.label not in STANDS_ON_LEGS and bottom - h > max(MAX_DROP_M, SLENDER_LEGS * narrow)
            legged = b.asset.label in STANDS_ON_LEGS  # stands on its own (hidden) legs, not on a column
            if j in (FLOOR, BACKGROUND) and (slender or (hidden_under and not legged and bottom - h > max(MAX_DROP_M, HIDDEN_OWN_SHARE * b.height_m))):
                # Far above the floor or the background below, for its size: a static column
                # from there up to its bottom stands in for the hidden support (it stays put when
                # the object is picked up). Nearer (a bed's frame hidden by its own cover), or on
                # another object, it stands on legs.
                b.pad_bottom_m, h, j, k = h, bottom, BACKGROUND, -1
            b.parent, b.support_surface = j, k
            # On a merged top, it rests on the step under it (the pushes keep it over that step).
            b.step_face = steps.get((j, k))
            if j == BACKGROUND and b.pad_bottom_m is None:
                full = pad_frame(b, h)[0]
                # Kept only where a neighbour cut it back (the whole rectangle follows the body's
                # pieces when the layout trims them).
                b.pad_rect_m = None if np.allclose(pad_rects[h], full) else pad_rects[h]
            if j >= 0:
                bodies[j].children.append(i)
            parent_name = bodies[j].name if j >= 0 else ("background" if j == BACKGROUND else "floor")
        elif (b.fixed and _near_wall(b, walls)) or mountable:
            if b.fixed:
                b.parent = WALL  # built-in furniture hangs on the wall
            else:
                _mount(b, "wall")
            h = bottom
            parent_name = "wall"
        elif b.fixed:
            # Welded to the room by its category (a sink set in a counter the photo keeps as
            # background, an oven under a hob): it stays where seen, as it is.
            _mount(b, "room")
            h = bottom
            parent_name = "room"
        else:
            b.parent = UNSUPPORTED
            if pad_blocked:
                b.unsupported_reason = BLOCKED_PAD_REASON
            else:
                b.unsupported_reason = "hangs: the camera saw empty space under it" if seen_under else "nothing seen under it to rest on"
            h = bottom
            parent_name = "none"
        # The gap as observed: the child's and the support's initial heights.
        if b.parent >= 0:
            s = bodies[b.parent]
            h_obs = h + float(s.initial_position_m[2] - s.position_m[2])
        else:
            h_obs = h
        edges.append(SupportEdge(child=b.name, parent=parent_name, contact_gap_m=float(bottom - h_obs)))
        if bottom - h > max_lower_m and b.parent not in (UNSUPPORTED, WALL) and b.asset.kind is not AssetKind.DEFORMABLE:
            # Seen standing higher than its support: its feet were not seen (thin legs, a dark
            # plinth cut from its mask). It stays where it was seen, on legs down to the support.
            b.legs_m = float(bottom - h)
            b.hidden_support = hidden_under
        else:
            b.position_m[2] += h - bottom
        placed_lo[len(placed)] = b.position_m[:2] + b.lo_rel_m[:2]
        placed_hi[len(placed)] = b.position_m[:2] + b.hi_rel_m[:2]
        placed.append(i)
    return edges, order


def subtree(bodies: list[Body], i: int) -> list[int]:
    """Indices of body ``i`` and everything resting on it, directly or not (depth first)."""
    out, stack = [], [i]
    while stack:
        k = stack.pop()
        out.append(k)
        stack.extend(reversed(bodies[k].children))
    return out


def is_ancestor(bodies: list[Body], a: int, b: int) -> bool:
    """Whether ``a`` supports ``b`` directly or through a chain."""
    k = bodies[b].parent
    while k >= 0:
        if k == a:
            return True
        k = bodies[k].parent
    return False
