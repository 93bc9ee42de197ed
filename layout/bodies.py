"""The solver's working state for one object (internal to ``layout``; never passed between stages)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from layout.geometry import Piece, SupportSurface, box_piece, footprint, merged_top_surfaces, object_pieces, top_surfaces
from scene_builder.model import AssetKind, ObjectAsset


@dataclass(eq=False)
class Body:
    """One object while the solver moves it: fixed rotation, a position that changes.

    rotation: (3, 3) world_from_asset rotation (after yaw snapping).
    position_m: (3,) world_from_asset translation, updated in place by the solver.
    initial_position_m: (3,) the translation the solver started from.
    pieces / surfaces / footprint_rel_m: geometry relative to ``position_m`` in world axes.
    lo_rel_m, hi_rel_m: (3,) bounds of all pieces relative to ``position_m``.
    piece_lo_rel_m, piece_hi_rel_m: (K, 3) bounds of each piece relative to ``position_m``.
    com_rel_m: (3,) centre of mass relative to ``position_m``.
    """

    name: str
    asset: ObjectAsset
    rotation: np.ndarray
    position_m: np.ndarray
    initial_position_m: np.ndarray
    pieces: tuple[Piece, ...]
    surfaces: tuple[SupportSurface, ...]
    footprint_rel_m: np.ndarray
    lo_rel_m: np.ndarray
    hi_rel_m: np.ndarray
    piece_lo_rel_m: np.ndarray
    piece_hi_rel_m: np.ndarray
    com_rel_m: np.ndarray
    mass_kg: float
    fixed: bool
    parent: int = -1  # index of the supporting body; -1 floor, -2 wall, -3 background, -4 none
    support_surface: int = -1  # index into the parent's ``surfaces`` when parent >= 0
    children: list[int] = field(default_factory=list)
    # Why it is left where seen as static background (parent -4), one line for the report.
    unsupported_reason: str = ""
    # Seen this far above its support: it keeps its height and stands on collision legs.
    legs_m: float = 0.0
    hidden_support: bool = False  # legs stand on a support found below a hidden underside
    pad_bottom_m: float | None = None  # its background pad is a column from here (hidden support)
    # Its pad's rectangle (lo_x, lo_y, hi_x, hi_y) in its own yawed axes relative to position_m,
    # when cut back clear of its neighbours (layout.background.clip_pad); None: its plan extent.
    pad_rect_m: np.ndarray | None = None
    # Bodies its collision pieces were cut apart from (layout.trim): they touch by construction,
    # with the cut's clearance; only a real overlap with them is a violation.
    trimmed_with: set[str] = field(default_factory=set)
    # Static only: movable bodies its collision caged, cut back out of their outlines (layout.cage).
    cut_for: list[str] = field(default_factory=list)
    # Welded to the room where seen: "wall" (a wall-mountable thing against a wall with nothing
    # under it) or "room" (a fixed-category thing with nothing under it); "" = not mounted.
    mounted: str = ""
    # ``surfaces`` holds the top face of each piece first, then the merged tops
    # (layout.geometry.merged_top_surfaces) from this index on.
    merged_from: int = 0
    # Resting on a merged top: the step of it under this body (layout.support.step_face), the
    # face its support region is kept on; None otherwise.
    step_face: SupportSurface | None = None

    @property
    def bottom_m(self) -> float:
        return float(self.position_m[2] + self.lo_rel_m[2])

    @property
    def height_m(self) -> float:
        return float(self.hi_rel_m[2] - self.lo_rel_m[2])

    def world_from_asset(self) -> np.ndarray:
        t = np.eye(4)
        t[:3, :3] = self.rotation
        t[:3, 3] = self.position_m
        return t

    def world_vertices(self) -> np.ndarray:
        """(V, 3) all collision vertices in the world."""
        return np.concatenate([p.verts_rel_m for p in self.pieces]) + self.position_m


#: Collision legs: side between LEG_MIN_M and LEG_MAX_M (LEG_SHARE of the narrower plan extent),
#: at the corners of the object's plan rectangle, reaching LEG_INTO_M up into the object.
LEG_SHARE = 0.15
LEG_MIN_M = 0.02
LEG_MAX_M = 0.05
LEG_INTO_M = 0.02


def with_legs(b: Body) -> Body:
    """``b`` with four collision legs (boxes in its root part's collision pieces, no mass) from
    its bottom down ``b.legs_m`` to its support, at the corners of its plan rectangle: it stands
    where it was seen although its feet were not seen. Pose, support and flags are kept."""
    import dataclasses

    from scene_builder.model import TriangleMesh

    asset = b.asset
    verts = np.concatenate([p.verts_rel_m for p in b.pieces]) @ b.rotation  # asset axes, relative
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    side = float(np.clip(LEG_SHARE * min(hi[0] - lo[0], hi[1] - lo[1]), LEG_MIN_M, LEG_MAX_M))
    z0, z1 = lo[2] - b.legs_m, lo[2] + min(LEG_INTO_M, hi[2] - lo[2])
    legs = []
    for x in (lo[0], hi[0] - side):
        for y in (lo[1], hi[1] - side):
            c = np.array([[x + dx, y + dy, z] for dx in (0.0, side) for dy in (0.0, side) for z in (z0, z1)])
            legs.append(TriangleMesh(c, _BOX_FACES_ASSET))
    root = asset.root
    parts = tuple(dataclasses.replace(p, collision=p.collision + tuple(legs)) if p is root else p for p in asset.parts)
    return rebuilt(b, dataclasses.replace(asset, parts=parts))


def rebuilt(b: Body, asset: ObjectAsset) -> Body:
    """A body for ``asset`` (``b``'s asset with changed collision pieces) at ``b``'s pose, with
    ``b``'s support, flags and starting position."""
    new = make_body(asset, b.world_from_asset())
    new.initial_position_m = b.initial_position_m
    new.parent, new.support_surface, new.children, new.fixed = b.parent, b.support_surface, b.children, b.fixed
    new.unsupported_reason, new.legs_m, new.hidden_support, new.pad_bottom_m = b.unsupported_reason, b.legs_m, b.hidden_support, b.pad_bottom_m
    new.pad_rect_m = b.pad_rect_m
    new.trimmed_with = set(b.trimmed_with)
    new.mounted = b.mounted
    new.step_face = b.step_face
    return new


# Corner k of a box has x = hi when k & 4, y = hi when k & 2, z = hi when k & 1; faces outward.
_BOX_FACES_ASSET = np.array(
    [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]],
    dtype=np.int64,
)


def make_body(asset: ObjectAsset, world_from_asset: np.ndarray) -> Body:
    """Working state of ``asset`` placed at ``world_from_asset`` (4, 4)."""
    rotation = np.array(world_from_asset[:3, :3], dtype=np.float64)
    position = np.array(world_from_asset[:3, 3], dtype=np.float64)
    if asset.kind is AssetKind.DEFORMABLE:
        # The flex fills the bounding box of the visual meshes (exporters.mjcf.flex_grid).
        lo_a = np.min([p.visual.bounds_m[0] for p in asset.parts], axis=0)
        hi_a = np.max([p.visual.bounds_m[1] for p in asset.parts], axis=0)
        pieces: tuple[Piece, ...] = (box_piece(lo_a, hi_a, rotation),)
    else:
        pieces = object_pieces(asset, rotation)
    lo = np.min([p.lo_rel_m for p in pieces], axis=0)
    hi = np.max([p.hi_rel_m for p in pieces], axis=0)
    band = max(0.01, 0.05 * float(hi[2] - lo[2]))
    masses = np.array([p.inertial.mass_kg for p in asset.parts])
    com_asset = np.sum([p.inertial.mass_kg * p.inertial.com_m for p in asset.parts], axis=0) / masses.sum()
    return Body(
        name=asset.name,
        asset=asset,
        rotation=rotation,
        position_m=position,
        initial_position_m=position.copy(),
        pieces=pieces,
        surfaces=(tops := top_surfaces(pieces)) + merged_top_surfaces(tops),
        merged_from=len(tops),
        footprint_rel_m=footprint(pieces, band),
        lo_rel_m=lo,
        hi_rel_m=hi,
        piece_lo_rel_m=np.array([p.lo_rel_m for p in pieces]),
        piece_hi_rel_m=np.array([p.hi_rel_m for p in pieces]),
        com_rel_m=rotation @ com_asset,
        mass_kg=float(masses.sum()),
        fixed=bool(asset.is_fixed),
    )
