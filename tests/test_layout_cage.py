"""layout.cage: a movable object held in a static object's collision is freed by cutting the
static pieces back out of its outline, and nothing else changes."""

from __future__ import annotations

import numpy as np

from layout.cage import CAGE_TRAVEL_M, caged, uncage
from scene_builder.model import Plane
from tests.fixtures_scenes import WOOD, box_asset, pose


def _box(lo, hi) -> np.ndarray:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


# An open shelf against the wall x = 0, its compartments open towards +x: back board, two sides,
# bottom and top boards (0.4 m deep, 0.8 m wide, 1 m high).
SHELF = [
    _box((0.0, -0.4, 0.0), (0.02, 0.4, 1.0)),
    _box((0.0, -0.4, 0.0), (0.4, -0.38, 1.0)),
    _box((0.0, 0.38, 0.0), (0.4, 0.4, 1.0)),
    _box((0.0, -0.4, 0.0), (0.4, 0.4, 0.02)),
    _box((0.0, -0.4, 0.98), (0.4, 0.4, 1.0)),
]
WALL = (Plane(np.array([1.0, 0.0, 0.0]), 0.0, "wall", 100),)


def _slab(x0: float):
    """A static "bed" slab from x0 to 2.5 m, 0.74 m wide (1 cm from the shelf's sides), 0.4-0.6 m
    high, and its placement."""
    length = 2.5 - x0
    asset = box_asset("bed", (length, 0.74, 0.2), WOOD, is_fixed=True, label="bed")
    return asset, pose(np.eye(3), (x0 + length / 2.0, 0.0, 0.4))


def _pieces(asset, t) -> list[np.ndarray]:
    return [p.vertices_m @ t[:3, :3].T + t[:3, 3] for part in asset.parts for p in part.collision]


def test_a_slab_inside_the_shelf_cages_it_and_is_cut_back_to_the_shelf_front():
    asset, t = _slab(0.021)  # into the compartment, 1 mm from the back board
    statics = _pieces(asset, t)
    assert caged(SHELF, statics, WALL)
    assert not caged(SHELF, statics, ())  # without the wall it slides back, off the slab
    (cut,) = uncage(SHELF, [(asset, t)], WALL)
    assert cut is not asset and cut.name == asset.name and cut.parts[0].visual is asset.parts[0].visual
    kept = _pieces(cut, t)
    assert len(kept) == 1
    lo, hi = kept[0].min(axis=0), kept[0].max(axis=0)
    # Cut at the shelf's front (x = 0.4, plus the trim clearance): the rest of the slab is kept.
    assert np.allclose(lo, [0.402, -0.37, 0.4], atol=1e-6) and np.allclose(hi, [2.5, 0.37, 0.6], atol=1e-6)
    assert not caged(SHELF, kept, WALL)


def test_a_slab_outside_the_shelf_is_left_alone():
    asset, t = _slab(0.4 + CAGE_TRAVEL_M + 0.01)
    statics = _pieces(asset, t)
    assert not caged(SHELF, statics, WALL)
    assert uncage(SHELF, [(asset, t)], WALL) is None


def test_a_neighbour_touching_its_side_is_not_cut():
    """A static cabinet standing against the shelf's side, 5 mm into its outline (as hulls of
    neighbours do), is not what holds it: it keeps its collision."""
    neighbour = box_asset("cabinet", (0.4, 0.5, 0.9), WOOD, is_fixed=True, label="cabinet")
    t = pose(np.eye(3), (0.2, 0.4 - 0.005 + 0.25, 0.0))
    slab, ts = _slab(0.021)
    assert caged(SHELF, _pieces(slab, ts) + _pieces(neighbour, t), WALL)
    cut_slab, kept_neighbour = uncage(SHELF, [(slab, ts), (neighbour, t)], WALL)
    assert kept_neighbour is neighbour and cut_slab is not slab
    # Held between that neighbour and a second one on its other side (and the wall), with no
    # slab: nothing reaches into it, nothing is cut, it stays caged.
    other = pose(np.eye(3), (0.2, -0.4 + 0.005 - 0.25, 0.0))
    front = box_asset("counter", (0.5, 1.2, 0.9), WOOD, is_fixed=True, label="counter")
    tf = pose(np.eye(3), (0.4 - 0.005 + 0.25, 0.0, 0.0))
    statics = [(neighbour, t), (neighbour, other), (front, tf)]
    assert caged(SHELF, [v for a, ta in statics for v in _pieces(a, ta)], WALL)
    assert uncage(SHELF, statics, WALL) is None



def test_a_part_whose_only_piece_sits_inside_the_caged_object_keeps_it():
    """A static cabinet whose door handle (a part with one small collision piece) lies wholly
    inside the shelf's compartment, the wall behind the shelf and a neighbour touching its other
    side: every direction that frees the shelf would cut the handle's only piece away, leaving a
    part with no collision (``ValueError: Part door_handle: needs at least one collision piece``
    on an unseen photo). A direction whose cuts would take a part's last piece does not qualify:
    the shelf stays caged and every part keeps its piece."""
    from scene_builder.model import AssetKind, Joint, JointType, ObjectAsset

    from tests.fixtures_scenes import part_from_boxes

    body = part_from_boxes("body", [((0.6, 0.5, 0.0), (1.0, 0.9, 0.9))], WOOD)
    lo, hi = (0.03, -0.37, 0.7), (0.07, -0.33, 0.74)  # 4 cm inside the back-left corner
    handle = part_from_boxes("door_handle", [(lo, hi)], WOOD, parent="body",
                             joint=Joint(JointType.FIXED, np.array([0.0, 0.0, 1.0]), np.array(lo)))
    cabinet = ObjectAsset("cabinet", "cabinet", AssetKind.ARTICULATED, (body, handle), np.array([0.97, 0.57, 0.9]), is_fixed=True)
    neighbour = box_asset("counter", (0.4, 0.5, 0.9), WOOD, is_fixed=True, label="counter")
    statics = [(cabinet, np.eye(4)), (neighbour, pose(np.eye(3), (0.2, -0.4 + 0.005 - 0.25, 0.0)))]
    assert caged(SHELF, [v for a, t in statics for v in _pieces(a, t)], WALL)
    # Before parts kept their last piece this raised ValueError (the handle cut away).
    assert uncage(SHELF, statics, WALL) is None


def test_sub_millimetre_pieces_far_apart_are_measured_not_refused():
    """Two 0.2 mm cubes (the smallest solid piece generation makes) 5 cm apart: MuJoCo summing
    their own inertias refused the distance model ('inertia must have positive eigenvalues');
    the cage check and the solver's narrow phase answer instead."""
    from layout.geometry import Piece
    from layout.narrowphase import ConvexWorld

    speck = _box(np.zeros(3), np.full(3, 2e-4))
    far = speck + np.array([0.05, 0.0, 0.0])
    assert not caged([speck], [far], ())  # free to slide every way
    pieces = [Piece(v, np.zeros((0, 2), np.int64), v.min(0), v.max(0), np.zeros((0, 2))) for v in (speck, far)]
    world = ConvexWorld([tuple(pieces)])
    assert world.model.ngeom == 2
