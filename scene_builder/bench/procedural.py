"""Procedural rooms with exact ground truth: the synthetic benchmark suite and the demo input.

This module decides a room from a seed (pure numpy); :mod:`scene_builder.bench.render` builds
and renders it with MuJoCo and writes the sample folder; :mod:`scene_builder.bench.truth` reads
the ground truth back and scores a built scene against it.

A room is a floor, two or three walls (a corner the camera looks into) and furniture of the
project vocabulary built from MuJoCo primitives (a table is a top and four legs, a cabinet a shell
of panels with doors and drawers as separate bodies on joints, a sofa a base, a back and two arms,
a pillow an ellipsoid ...). Everything is decided by :func:`make_room` from a seed (pure numpy, no
MuJoCo), then :func:`scene_builder.bench.render.render_room` builds it with ``mujoco.MjSpec``, renders RGB, metric planar
depth and instance ids from a Kinect-like camera and writes a sample folder in the format of
``../shared/data/real/*`` (``rgb.png``, ``depth.png``, ``camera.json``, ``meta.json``) plus
``instances.png`` and, when depth noise is on, the clean ``depth_gt.png``.

Ground-truth conventions (also written into ``meta.json``)
---------------------------------------------------------
* World frame: Z up, floor ``z = 0``, metres (the frame of :mod:`scene_builder.model`).
* Object frame: the asset frame of the data model: origin at the centre of the bottom face of the
  object's bounding box, Z up, **front (doors, drawers, seat) facing +X**.
* ``position_m``: the centre of the object's gravity-aligned bounding box in the world.
  ``size_m``: full extents (x, y, z) of that box in the object frame (x = depth, y = width).
  ``yaw_rad``: rotation of the object frame about world +Z (counter-clockwise seen from above).
  ``world_from_object``: the 4x4 pose of the object frame (= translation to the bottom centre).
* Joints: axis and anchor in the object frame at the rest pose (doors closed, drawers in), limits
  in radians (revolute) or metres (prismatic), positive = opening.
* ``instances.png``: uint16, 0 = floor, walls or nothing; k = the object with ``object_id`` k.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scene_builder import frames
from scene_builder.model import AssetKind, Camera, CameraIntrinsics
from scene_builder.vocabulary import category as vocab_category

__all__ = [
    "DepthNoise",
    "Look",
    "PartJoint",
    "Primitive",
    "RoomObject",
    "RoomSpec",
    "Wall",
    "make_room",
]

# Furniture the generator can stand on the floor, with sampling weights.
FLOOR_CATEGORIES: dict[str, float] = {
    "table": 2.0,
    "chair": 2.0,
    "cabinet": 2.0,
    "drawer_unit": 1.0,
    "shelf": 1.5,
    "sofa": 1.0,
    "box": 1.5,
    "bin": 0.5,
}
# Small things the generator puts on other objects, with sampling weights.
ITEM_CATEGORIES: dict[str, float] = {"box": 1.5, "book": 1.5, "bottle": 1.0, "mug": 1.0, "bowl": 0.7, "laptop": 0.7}
# Furniture that stands with its back against a wall, facing into the room.
_WALL_BACKED = {"cabinet", "drawer_unit", "shelf", "sofa"}
# Densities (kg/m^3) of the solid primitives the generator builds each category from.
DENSITY_KG_M3: dict[str, float] = {
    "table": 650.0,  # solid wood
    "chair": 650.0,
    "cabinet": 700.0,  # MDF / particle board panels
    "drawer_unit": 700.0,
    "shelf": 650.0,
    "sofa": 90.0,  # upholstered foam on a light frame, averaged over the solid volume
    "box": 120.0,  # a cardboard box with some contents
    "bin": 150.0,
    "pillow": 40.0,
    "book": 700.0,
    "bottle": 600.0,
    "mug": 900.0,
    "bowl": 700.0,
    "laptop": 1500.0,
}
_PANEL_M = 0.018  # furniture panel thickness
_GAP_M = 0.003  # clearance between doors / drawers and the carcass


# --------------------------------------------------------------------------------------------
# The room description (pure data)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Look:
    """How a surface renders. rgba: base colour in [0, 1]. texture: ``""`` (plain), ``"speckle"``
    (flat with random marks), ``"checker"`` or ``"gradient"`` (MuJoCo builtin textures).
    rgba2: second texture colour. texrepeat: repeats per metre (planes) or per face (boxes)."""

    rgba: tuple[float, float, float, float]
    texture: str = ""
    rgba2: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    texrepeat: tuple[float, float] = (1.0, 1.0)


@dataclass(frozen=True)
class Primitive:
    """One MuJoCo primitive of an object, at the rest pose, in the object frame.

    body: ``""`` for the object's root body, else the part name (``door_0``, ``drawer_1``, ``lid``).
    shape: ``"box"``, ``"cylinder"`` (vertical axis) or ``"ellipsoid"``.
    half_size_m: box half extents; cylinder (radius, radius, half height); ellipsoid radii.
    center_m: centre in the object frame.
    """

    body: str
    shape: str
    half_size_m: tuple[float, float, float]
    center_m: tuple[float, float, float]
    look: Look

    @property
    def volume_m3(self) -> float:
        a, b, c = self.half_size_m
        if self.shape == "box":
            return 8.0 * a * b * c
        if self.shape == "cylinder":
            return math.pi * a * a * 2.0 * c
        return 4.0 / 3.0 * math.pi * a * b * c


@dataclass(frozen=True)
class PartJoint:
    """Ground-truth joint of a moving part. type: ``"revolute"`` or ``"prismatic"``. axis (unit)
    and anchor_m in the object frame at rest; lower/upper in rad or m, positive opens."""

    part: str
    type: str
    axis: tuple[float, float, float]
    anchor_m: tuple[float, float, float]
    lower: float
    upper: float


@dataclass(frozen=True)
class RoomObject:
    """One object of a procedural room (see the module docstring for the conventions).

    object_id: 1-based, the value of the object's pixels in ``instances.png``.
    position_m: (3,) bounding-box centre in the world. size_m: (3,) extents in the object frame.
    support: ``"floor"`` or the name of the object it rests on.
    """

    object_id: int
    name: str
    category: str
    position_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    yaw_rad: float
    support: str
    primitives: tuple[Primitive, ...]
    joints: tuple[PartJoint, ...] = ()

    @property
    def kind(self) -> AssetKind:
        if self.joints:
            return AssetKind.ARTICULATED
        return vocab_category(self.category).kind

    @property
    def mass_kg(self) -> float:
        return float(DENSITY_KG_M3[self.category] * sum(p.volume_m3 for p in self.primitives))

    @property
    def world_from_object(self) -> np.ndarray:
        """(4, 4) pose of the object frame (origin at the bottom centre of the box)."""
        bottom = np.array(self.position_m) - np.array([0.0, 0.0, self.size_m[2] / 2.0])
        return frames.pose(frames.rot_z(self.yaw_rad), bottom)

    @property
    def top_z_m(self) -> float:
        return float(self.position_m[2] + self.size_m[2] / 2.0)


@dataclass(frozen=True, eq=False)
class Wall:
    """A wall plane ``normal . x + offset_m = 0`` (normal horizontal, into the room), rendered as
    a plane of half extents ``half_length_m`` x ``height_m / 2`` centred at ``center_m``."""

    name: str
    normal: tuple[float, float, float]
    offset_m: float
    center_m: tuple[float, float, float]
    half_length_m: float
    height_m: float
    look: Look


@dataclass(frozen=True)
class DepthNoise:
    """Sensor-like depth corruption applied by :func:`render_room`.

    rel_sigma: standard deviation of the Gaussian noise as a fraction of the depth (Kinect-class
    sensors: about 0.3 % at 1 m to 1 % at 4 m; 0.5 % is in between). holes: number of random
    elliptical holes. edge_dropout: probability that a pixel at a depth discontinuity (> 5 cm
    jump to a neighbour) is invalid. max_range_m: depth beyond is invalid. Depth is always
    quantised to millimetres (the PNG format).
    """

    rel_sigma: float = 0.005
    holes: int = 6
    edge_dropout: float = 0.6
    max_range_m: float = 8.0


@dataclass(frozen=True, eq=False)
class RoomSpec:
    """A procedural room: everything :func:`render_room` needs, decided by ``seed``.

    room_size_m: (x, y, wall height) of the room's rectangle ``[0, x] x [0, y]``.
    """

    seed: int
    room_size_m: tuple[float, float, float]
    floor_look: Look
    walls: tuple[Wall, ...]
    camera: Camera
    objects: tuple[RoomObject, ...]
    noise: DepthNoise | None = None
    light_pos_m: tuple[float, float, float] = (2.0, 2.0, 2.8)

    @property
    def name(self) -> str:
        return f"procedural_room_s{self.seed:04d}"

    def object(self, name: str) -> RoomObject:
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(name)


# --------------------------------------------------------------------------------------------
# Colours
# --------------------------------------------------------------------------------------------

_WOODS = [(0.55, 0.38, 0.22), (0.66, 0.50, 0.33), (0.42, 0.28, 0.17), (0.74, 0.60, 0.42), (0.30, 0.21, 0.14)]
_NEUTRALS = [(0.85, 0.85, 0.82), (0.62, 0.62, 0.60), (0.35, 0.35, 0.36), (0.20, 0.20, 0.22), (0.78, 0.74, 0.66)]
_FABRICS = [(0.25, 0.32, 0.45), (0.45, 0.22, 0.20), (0.30, 0.40, 0.30), (0.55, 0.52, 0.48), (0.62, 0.55, 0.40)]
_BRIGHT = [(0.80, 0.20, 0.15), (0.15, 0.45, 0.75), (0.90, 0.75, 0.20), (0.20, 0.60, 0.35), (0.90, 0.90, 0.90)]


def _jitter(rng: np.random.Generator, rgb, amount: float = 0.05) -> tuple[float, float, float, float]:
    c = np.clip(np.asarray(rgb) + rng.uniform(-amount, amount, 3), 0.02, 0.98)
    return (float(c[0]), float(c[1]), float(c[2]), 1.0)


def _look(rng: np.random.Generator, palette, texture_p: float = 0.3) -> Look:
    base = _jitter(rng, palette[rng.integers(len(palette))])
    if rng.random() < texture_p:
        kind = ("speckle", "gradient", "checker")[rng.integers(3)]
        second = _jitter(rng, np.array(base[:3]) * rng.uniform(0.75, 0.95), 0.02)
        return Look(base, kind, second, (float(rng.integers(2, 6)),) * 2)
    return Look(base)


# --------------------------------------------------------------------------------------------
# Object builders: each returns (size_m, primitives, joints, surfaces) in the object frame.
# A surface is (z_top_m, x_half_m, y_half_m, x_centre_m, clearance_m) where items can be placed.
# --------------------------------------------------------------------------------------------

Surface = tuple[float, float, float, float, float]


def _box(body: str, center, half, look: Look) -> Primitive:
    return Primitive(body, "box", tuple(float(h) for h in half), tuple(float(c) for c in center), look)


def _cyl(body: str, center, radius: float, half_h: float, look: Look) -> Primitive:
    return Primitive(body, "cylinder", (float(radius), float(radius), float(half_h)), tuple(float(c) for c in center), look)


def _table(rng, look: Look):
    sx, sy, sz = rng.uniform(0.7, 0.95), rng.uniform(1.0, 1.6), rng.uniform(0.72, 0.78)
    t = rng.uniform(0.03, 0.045)
    prims = [_box("", (0, 0, sz - t / 2), (sx / 2, sy / 2, t / 2), look)]
    leg_look = look if rng.random() < 0.6 else _look(rng, _NEUTRALS, 0.0)
    inset, leg = rng.uniform(0.04, 0.1), rng.uniform(0.04, 0.06)
    round_legs = rng.random() < 0.4
    for ix in (-1, 1):
        for iy in (-1, 1):
            c = (ix * (sx / 2 - inset), iy * (sy / 2 - inset), (sz - t) / 2)
            prims.append(_cyl("", c, leg / 2, (sz - t) / 2, leg_look) if round_legs else _box("", c, (leg / 2, leg / 2, (sz - t) / 2), leg_look))
    surfaces = [(sz, sx / 2 - 0.05, sy / 2 - 0.05, 0.0, 1.0)]
    return (sx, sy, sz), prims, [], surfaces


def _chair(rng, look: Look):
    sx, sy = rng.uniform(0.45, 0.55), rng.uniform(0.42, 0.5)
    seat_h, sz, t, leg = rng.uniform(0.43, 0.47), rng.uniform(0.8, 0.95), 0.04, rng.uniform(0.03, 0.045)
    prims = [_box("", (0, 0, seat_h - t / 2), (sx / 2, sy / 2, t / 2), look)]
    for ix in (-1, 1):
        for iy in (-1, 1):
            prims.append(_box("", (ix * (sx / 2 - leg / 2), iy * (sy / 2 - leg / 2), (seat_h - t) / 2), (leg / 2, leg / 2, (seat_h - t) / 2), look))
    back_t = 0.03
    prims.append(_box("", (-sx / 2 + back_t / 2, 0, (seat_h + sz) / 2), (back_t / 2, sy / 2, (sz - seat_h) / 2), look))
    return (sx, sy, sz), prims, [], []


def _cabinet(rng, look: Look, drawers_only: bool = False):
    if drawers_only:
        sx, sy, sz = rng.uniform(0.42, 0.55), rng.uniform(0.45, 0.7), rng.uniform(0.6, 0.85)
    else:
        sx, sy, sz = rng.uniform(0.4, 0.55), rng.uniform(0.6, 1.0), rng.uniform(0.8, 1.0)
    p = _PANEL_M
    front_look = look if rng.random() < 0.6 else _look(rng, _WOODS + _NEUTRALS, 0.2)
    handle_look = Look((0.75, 0.75, 0.78, 1.0)) if rng.random() < 0.5 else Look((0.1, 0.1, 0.1, 1.0))
    handle_d = 0.02  # handles protrude this far; the doors sit behind them so the box is exact
    xf = sx / 2 - handle_d  # front face of doors / drawer fronts
    x_car = xf - p  # carcass front edge
    prims = [
        _box("", (-sx / 2 + p / 2, 0, sz / 2), (p / 2, sy / 2, sz / 2), look),  # back
        _box("", ((-sx / 2 + x_car) / 2, sy / 2 - p / 2, sz / 2), ((x_car + sx / 2) / 2, p / 2, sz / 2), look),  # sides
        _box("", ((-sx / 2 + x_car) / 2, -sy / 2 + p / 2, sz / 2), ((x_car + sx / 2) / 2, p / 2, sz / 2), look),
        _box("", ((-sx / 2 + x_car) / 2, 0, sz - p / 2), ((x_car + sx / 2) / 2, sy / 2 - p, p / 2), look),  # top
        _box("", ((-sx / 2 + x_car) / 2, 0, p / 2 + 0.05), ((x_car + sx / 2) / 2, sy / 2 - p, p / 2), look),  # bottom
        _box("", (x_car - p / 2, 0, 0.025), (p / 2, sy / 2 - p, 0.025), look),  # plinth
    ]
    joints: list[PartJoint] = []
    z0, z1 = 0.05 + p, sz - p  # opening between bottom and top panels
    y0, y1 = -sy / 2 + p, sy / 2 - p
    n_drawers = int(rng.integers(2, 5)) if drawers_only else int(rng.choice([0, 0, 1, 2]))
    drawer_h = (z1 - z0) / max(n_drawers, 1) if drawers_only else 0.16
    zd = z1
    inner_depth = x_car - (-sx / 2 + p)
    for i in range(n_drawers):
        name = f"drawer_{i}"
        lo, hi = zd - drawer_h + _GAP_M / 2, zd - _GAP_M / 2
        zc = (lo + hi) / 2
        prims.append(_box(name, (xf - p / 2, 0, zc), (p / 2, (y1 - y0) / 2 - _GAP_M, (hi - lo) / 2), front_look))
        tray_d = inner_depth - 0.03
        prims.append(_box(name, (x_car - tray_d / 2, 0, lo + 0.01), (tray_d / 2, (y1 - y0) / 2 - 0.01, 0.006), front_look))
        prims.append(_box(name, (xf + handle_d / 2, 0, zc), (handle_d / 2, min(0.08, (y1 - y0) / 4), 0.008), handle_look))
        joints.append(PartJoint(name, "prismatic", (1.0, 0.0, 0.0), (float(xf), 0.0, float(zc)), 0.0, float(0.8 * tray_d)))
        zd -= drawer_h
    if not drawers_only:
        n_doors = 1 if (sy < 0.7 or rng.random() < 0.3) else 2
        d_hi = zd - _GAP_M / 2
        width = (y1 - y0) / n_doors
        for i in range(n_doors):
            name = f"door_{i}"
            ya, yb = y0 + i * width + _GAP_M / 2, y0 + (i + 1) * width - _GAP_M / 2
            prims.append(_box(name, (xf - p / 2, (ya + yb) / 2, (z0 + d_hi) / 2), (p / 2, (yb - ya) / 2, (d_hi - z0) / 2), front_look))
            hinge_left = (n_doors == 2 and i == 0) or (n_doors == 1 and rng.random() < 0.5)
            # Hinge at the door's -y edge opens about -Z, at its +y edge about +Z (free edge swings to +X).
            hy, axis = (ya, (0.0, 0.0, -1.0)) if hinge_left else (yb, (0.0, 0.0, 1.0))
            handle_y = yb - 0.05 if hinge_left else ya + 0.05
            prims.append(_box(name, (xf + handle_d / 2, handle_y, (z0 + d_hi) / 2 + 0.1), (handle_d / 2, 0.008, 0.06), handle_look))
            joints.append(PartJoint(name, "revolute", axis, (float(xf - p / 2), float(hy), float((z0 + d_hi) / 2)), 0.0, float(np.radians(110))))
    surfaces = [(sz, sx / 2 - 0.06, sy / 2 - 0.05, -handle_d / 2, 1.0)]
    return (sx, sy, sz), prims, joints, surfaces


def _shelf(rng, look: Look):
    sx, sy, sz = rng.uniform(0.3, 0.4), rng.uniform(0.7, 1.0), rng.uniform(1.3, 1.9)
    p = _PANEL_M
    prims = [
        _box("", (-sx / 2 + p / 2, 0, sz / 2), (p / 2, sy / 2, sz / 2), look),
        _box("", (p / 2, sy / 2 - p / 2, sz / 2), ((sx - p) / 2, p / 2, sz / 2), look),
        _box("", (p / 2, -sy / 2 + p / 2, sz / 2), ((sx - p) / 2, p / 2, sz / 2), look),
        _box("", (p / 2, 0, sz - p / 2), ((sx - p) / 2, sy / 2 - p, p / 2), look),
        _box("", (p / 2, 0, 0.04 + p / 2), ((sx - p) / 2, sy / 2 - p, p / 2), look),
        _box("", (p / 2, 0, 0.02), ((sx - p) / 2, sy / 2 - p, 0.02), look),
    ]
    n_boards = int(rng.integers(2, 5))
    levels = np.linspace(0.04 + p, sz - p, n_boards + 2)[1:-1]
    surfaces: list[Surface] = [(0.04 + p, (sx - p) / 2 - 0.03, sy / 2 - p - 0.03, p / 2, levels[0] - p - 0.04 - p - 0.01)]
    for i, z in enumerate(levels):
        prims.append(_box("", (p / 2, 0, z - p / 2), ((sx - p) / 2, sy / 2 - p, p / 2), look))
        nxt = levels[i + 1] - p if i + 1 < len(levels) else sz - p
        surfaces.append((float(z), (sx - p) / 2 - 0.03, sy / 2 - p - 0.03, p / 2, float(nxt - z - 0.01)))
    return (sx, sy, sz), prims, [], surfaces


def _sofa(rng, look: Look):
    sx, sy, sz = rng.uniform(0.8, 0.95), rng.uniform(1.5, 2.2), rng.uniform(0.75, 0.9)
    seat_h, back_t, arm_w, arm_h = rng.uniform(0.4, 0.46), rng.uniform(0.15, 0.22), rng.uniform(0.12, 0.2), rng.uniform(0.55, 0.65)
    leg_look = Look((0.12, 0.1, 0.08, 1.0))
    leg_h = 0.06
    prims = [
        _box("", (back_t / 2, 0, (seat_h + leg_h) / 2), ((sx - back_t) / 2, sy / 2 - arm_w, (seat_h - leg_h) / 2), look),
        _box("", (-sx / 2 + back_t / 2, 0, (sz + leg_h) / 2), (back_t / 2, sy / 2, (sz - leg_h) / 2), look),
        _box("", (back_t / 2, sy / 2 - arm_w / 2, (arm_h + leg_h) / 2), ((sx - back_t) / 2, arm_w / 2, (arm_h - leg_h) / 2), look),
        _box("", (back_t / 2, -sy / 2 + arm_w / 2, (arm_h + leg_h) / 2), ((sx - back_t) / 2, arm_w / 2, (arm_h - leg_h) / 2), look),
    ]
    for ix in (-1, 1):
        for iy in (-1, 1):
            prims.append(_box("", (ix * (sx / 2 - 0.05), iy * (sy / 2 - 0.05), leg_h / 2), (0.025, 0.025, leg_h / 2), leg_look))
    surfaces = [(seat_h, (sx - back_t) / 2 - 0.05, sy / 2 - arm_w - 0.05, back_t / 2, 1.0)]
    return (sx, sy, sz), prims, [], surfaces


def _simple_box(rng, look: Look, small: bool = False):
    if small:
        sx, sy, sz = rng.uniform(0.12, 0.3), rng.uniform(0.12, 0.35), rng.uniform(0.08, 0.25)
    else:
        sx, sy, sz = rng.uniform(0.25, 0.5), rng.uniform(0.25, 0.6), rng.uniform(0.2, 0.5)
    surfaces = [(sz, sx / 2 - 0.03, sy / 2 - 0.03, 0.0, 1.0)]
    return (sx, sy, sz), [_box("", (0, 0, sz / 2), (sx / 2, sy / 2, sz / 2), look)], [], surfaces


def _cylinder_item(rng, look: Look, radius_range, height_range):
    r, h = rng.uniform(*radius_range), rng.uniform(*height_range)
    return (2 * r, 2 * r, h), [_cyl("", (0, 0, h / 2), r, h / 2, look)], [], []


def _book(rng, look: Look):
    sx, sy, sz = rng.uniform(0.15, 0.24), rng.uniform(0.12, 0.18), rng.uniform(0.02, 0.05)
    return (sx, sy, sz), [_box("", (0, 0, sz / 2), (sx / 2, sy / 2, sz / 2), look)], [], [(sz, sx / 2 - 0.02, sy / 2 - 0.02, 0.0, 1.0)]


def _laptop(rng, look: Look):
    sx, sy = rng.uniform(0.22, 0.26), rng.uniform(0.32, 0.38)
    base_t, lid_t = 0.014, 0.008
    sz = base_t + lid_t
    prims = [
        _box("", (0, 0, base_t / 2), (sx / 2, sy / 2, base_t / 2), look),
        _box("lid", (0, 0, base_t + lid_t / 2), (sx / 2, sy / 2, lid_t / 2), look),
    ]
    # The lid opens about the rear edge: rotating about -Y lifts its front (+X) edge.
    joints = [PartJoint("lid", "revolute", (0.0, -1.0, 0.0), (float(-sx / 2), 0.0, float(base_t)), 0.0, float(np.radians(120)))]
    return (sx, sy, sz), prims, joints, []


def _pillow(rng, look: Look):
    sx, sy, sz = rng.uniform(0.32, 0.42), rng.uniform(0.42, 0.58), rng.uniform(0.11, 0.16)
    return (sx, sy, sz), [Primitive("", "ellipsoid", (sx / 2, sy / 2, sz / 2), (0.0, 0.0, sz / 2), look)], [], []


def _build(category: str, rng: np.random.Generator):
    """(size_m, primitives, joints, surfaces) of a fresh object of ``category``."""
    if category == "table":
        return _table(rng, _look(rng, _WOODS + _NEUTRALS[:2], 0.3))
    if category == "chair":
        return _chair(rng, _look(rng, _WOODS + _NEUTRALS + _FABRICS[:2], 0.2))
    if category == "cabinet":
        return _cabinet(rng, _look(rng, _WOODS + _NEUTRALS, 0.25))
    if category == "drawer_unit":
        return _cabinet(rng, _look(rng, _WOODS + _NEUTRALS, 0.25), drawers_only=True)
    if category == "shelf":
        return _shelf(rng, _look(rng, _WOODS + _NEUTRALS, 0.2))
    if category == "sofa":
        return _sofa(rng, _look(rng, _FABRICS, 0.6))
    if category == "box":
        return _simple_box(rng, _look(rng, [(0.62, 0.47, 0.30), (0.70, 0.56, 0.38)] + _NEUTRALS[:1] + _BRIGHT[:2], 0.3))
    if category == "bin":
        return _cylinder_item(rng, _look(rng, _NEUTRALS + _BRIGHT, 0.0), (0.12, 0.18), (0.3, 0.45))
    raise ValueError(f"procedural rooms cannot build floor category {category!r}")


def _build_item(category: str, rng: np.random.Generator):
    if category == "box":
        return _simple_box(rng, _look(rng, [(0.62, 0.47, 0.30)] + _BRIGHT + _NEUTRALS, 0.3), small=True)
    if category == "book":
        return _book(rng, _look(rng, _BRIGHT + _FABRICS, 0.0))
    if category == "bottle":
        return _cylinder_item(rng, _look(rng, _BRIGHT + [(0.2, 0.5, 0.3)], 0.0), (0.03, 0.045), (0.18, 0.3))
    if category == "mug":
        return _cylinder_item(rng, _look(rng, _BRIGHT + _NEUTRALS, 0.0), (0.04, 0.05), (0.08, 0.11))
    if category == "bowl":
        return _cylinder_item(rng, _look(rng, _BRIGHT + _NEUTRALS, 0.0), (0.07, 0.1), (0.05, 0.08))
    if category == "laptop":
        return _laptop(rng, _look(rng, [(0.25, 0.25, 0.27), (0.7, 0.7, 0.72)], 0.0))
    if category == "pillow":
        return _pillow(rng, _look(rng, _FABRICS + _BRIGHT, 0.5))
    raise ValueError(f"procedural rooms cannot build item category {category!r}")


# --------------------------------------------------------------------------------------------
# Placement: sample and reject, with part-level oriented boxes
# --------------------------------------------------------------------------------------------


@dataclass
class _Placed:
    obj: RoomObject
    boxes: np.ndarray  # (P, 7): centre xyz, half xyz, yaw (gravity-aligned world boxes of the parts)
    surfaces: list[Surface] = field(default_factory=list)
    items: int = 0


def _world_boxes(prims: tuple[Primitive, ...], world_from_object: np.ndarray, yaw: float) -> np.ndarray:
    """(P, 7) gravity-aligned world boxes (centre, half extents, yaw) bounding each primitive."""
    out = np.zeros((len(prims), 7))
    for i, p in enumerate(prims):
        out[i, :3] = frames.transform_points(world_from_object, np.array([p.center_m]))[0]
        out[i, 3:6] = p.half_size_m
        out[i, 6] = yaw
    return out


def _boxes_overlap(a: np.ndarray, b: np.ndarray, margin_m: float) -> bool:
    """Whether any box of (P, 7) ``a`` comes within ``margin_m`` of any box of (Q, 7) ``b``.

    A separating-axis test of yaw-rotated rectangles plus a z-interval test, vectorised over all
    pairs (shapely would cost a Python object per pair in the sampling loop)."""
    az, bz = a[:, None, :], b[None, :, :]
    if not np.any(np.abs(az[..., 2] - bz[..., 2]) < az[..., 5] + bz[..., 5] + margin_m):
        return False
    sep = np.abs(az[..., 2] - bz[..., 2]) >= az[..., 5] + bz[..., 5] + margin_m
    d = bz[..., :2] - az[..., :2]
    for yaw_src in (az[..., 6], bz[..., 6]):
        for k in range(2):
            ang = yaw_src + k * np.pi / 2
            axis = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
            dist = np.abs(np.sum(d * axis, axis=-1))
            ra = _proj_radius(az, axis)
            rb = _proj_radius(bz, axis)
            sep |= dist >= ra + rb + margin_m
    return bool(np.any(~sep))


def _proj_radius(boxes: np.ndarray, axis: np.ndarray) -> np.ndarray:
    c, s = np.cos(boxes[..., 6]), np.sin(boxes[..., 6])
    ex = np.stack([c, s], axis=-1)
    ey = np.stack([-s, c], axis=-1)
    return boxes[..., 3] * np.abs(np.sum(ex * axis, -1)) + boxes[..., 4] * np.abs(np.sum(ey * axis, -1))


def _box_corners(center, size, yaw: float) -> np.ndarray:
    """(8, 3) corners of a gravity-aligned box."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    local = signs * np.asarray(size) / 2.0
    return local @ frames.rot_z(yaw).T + np.asarray(center)


def _visible_enough(camera: Camera, center, size, yaw: float, min_in: int = 5) -> bool:
    """The box centre projects into the image (10 px margin) at 1-6.5 m, and at least
    ``min_in`` of its 8 corners project into the image in front of the camera."""
    k = camera.intrinsics
    cam_from_world = np.linalg.inv(camera.world_from_camera)
    pts = frames.transform_points(cam_from_world, np.vstack([np.asarray(center)[None], _box_corners(center, size, yaw)]))
    if not 1.0 <= pts[0, 2] <= 6.5:
        return False
    front = pts[:, 2] > 0.3
    uv = np.full((len(pts), 2), -1e9)
    uv[front] = k.project(pts[front])
    inside = front & (uv[:, 0] > 10) & (uv[:, 0] < k.width_px - 10) & (uv[:, 1] > 10) & (uv[:, 1] < k.height_px - 10)
    return bool(inside[0] and inside[1:].sum() >= min_in)


# --------------------------------------------------------------------------------------------
# make_room
# --------------------------------------------------------------------------------------------


def _make_camera(rng: np.random.Generator, room_x: float, room_y: float) -> Camera:
    k = CameraIntrinsics(
        fx_px=float(rng.uniform(515.0, 530.0)),
        fy_px=float(rng.uniform(515.0, 530.0)),
        cx_px=float(319.5 + rng.uniform(-6.0, 6.0)),
        cy_px=float(239.5 + rng.uniform(-6.0, 6.0)),
        width_px=640,
        height_px=480,
        source="file",
    )
    pos = np.array([rng.uniform(0.35, 0.8), rng.uniform(0.35, 0.25 * room_y + 0.35), rng.uniform(1.2, 1.7)])
    corner = np.array([room_x, room_y])
    yaw = float(np.arctan2(corner[1] - pos[1], corner[0] - pos[0]) + rng.uniform(-0.15, 0.15))
    pitch = float(np.radians(rng.uniform(8.0, 20.0)))
    z_c = np.array([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), -np.sin(pitch)])
    x_c = np.array([np.sin(yaw), -np.cos(yaw), 0.0])
    y_c = np.cross(z_c, x_c)
    return Camera(k, frames.pose(np.stack([x_c, y_c, z_c], axis=1), pos))


def make_room(seed: int, n_objects: int = 6, noise: bool = False, categories: tuple[str, ...] | None = None) -> RoomSpec:
    """Sample a room with ``n_objects`` objects (fewer only if nothing more fits), decided by ``seed``.

    categories: floor furniture to draw from (default: every key of ``FLOOR_CATEGORIES``); items
    on top (books, mugs, boxes, a laptop, a pillow on a sofa) are added between them.
    noise: corrupt the rendered depth like a sensor (:class:`DepthNoise` defaults).
    Pure numpy: no MuJoCo here, see :func:`render_room`.
    """
    if n_objects < 1:
        raise ValueError(f"n_objects must be at least 1, got {n_objects}")
    floor_cats = tuple(categories) if categories else tuple(FLOOR_CATEGORIES)
    unknown = [c for c in floor_cats if c not in FLOOR_CATEGORIES]
    if unknown:
        raise ValueError(f"unknown floor categories {unknown}; choose from {sorted(FLOOR_CATEGORIES)}")
    rng = np.random.default_rng(seed)
    lx, ly, lz = float(rng.uniform(4.0, 6.0)), float(rng.uniform(4.0, 6.0)), float(rng.uniform(2.5, 2.9))
    camera = _make_camera(rng, lx, ly)

    # Floor and walls: a back wall x = lx, a side wall y = ly, sometimes the other side wall y = 0.
    floor_tex = ("checker", "speckle", "gradient")[rng.integers(3)]
    floor_rgb = _jitter(rng, (_WOODS + _NEUTRALS)[rng.integers(10)])
    floor_look = Look(floor_rgb, floor_tex, _jitter(rng, np.array(floor_rgb[:3]) * rng.uniform(0.7, 0.9), 0.02), (float(rng.uniform(1.0, 3.0)),) * 2)
    wall_rgb = _jitter(rng, _NEUTRALS[rng.integers(2)] if rng.random() < 0.7 else _FABRICS[rng.integers(5)], 0.05)
    walls = [
        Wall("wall_0", (-1.0, 0.0, 0.0), lx, (lx, ly / 2, lz / 2), ly / 2, lz, Look(wall_rgb, "gradient", _jitter(rng, np.array(wall_rgb[:3]) * 0.8, 0.02))),
        Wall("wall_1", (0.0, -1.0, 0.0), ly, (lx / 2, ly, lz / 2), lx / 2, lz, Look(_jitter(rng, wall_rgb[:3], 0.04), "gradient", _jitter(rng, np.array(wall_rgb[:3]) * 0.85, 0.02))),
    ]
    if rng.random() < 0.5:
        walls.append(Wall("wall_2", (0.0, 1.0, 0.0), 0.0, (lx / 2, 0.0, lz / 2), lx / 2, lz, Look(_jitter(rng, wall_rgb[:3], 0.04), "speckle", _jitter(rng, np.array(wall_rgb[:3]) * 0.9, 0.02), (2.0, 2.0))))

    placed: list[_Placed] = []
    counts: dict[str, int] = {}
    weights = np.array([FLOOR_CATEGORIES[c] for c in floor_cats])
    weights = weights / weights.sum()
    item_cats = tuple(ITEM_CATEGORIES)
    item_w = np.array([ITEM_CATEGORIES[c] for c in item_cats])
    item_w = item_w / item_w.sum()
    failures = 0
    while len(placed) < n_objects and failures < 60:
        floor_objects = sum(1 for p in placed if p.obj.support == "floor")
        hosts = [p for p in placed if p.surfaces and p.items < 3]
        sofas = [p for p in placed if p.obj.category == "sofa" and p.items == 0]
        add_item = hosts and floor_objects >= 2 and rng.random() < 0.4
        ok = False
        if sofas and rng.random() < 0.7:
            ok = _try_item(rng, "pillow", sofas[0], placed, counts, camera)
        elif add_item:
            host = hosts[rng.integers(len(hosts))]
            cat = "box" if host.obj.category == "box" else str(rng.choice(item_cats, p=item_w))
            ok = _try_item(rng, cat, host, placed, counts, camera)
        else:
            ok = _try_floor(rng, str(rng.choice(floor_cats, p=weights)), placed, counts, camera, walls, lx, ly)
        failures += 0 if ok else 1
    return RoomSpec(
        seed=int(seed),
        room_size_m=(lx, ly, lz),
        floor_look=floor_look,
        walls=tuple(walls),
        camera=camera,
        objects=tuple(p.obj for p in placed),
        noise=DepthNoise() if noise else None,
        light_pos_m=(float(lx * rng.uniform(0.3, 0.7)), float(ly * rng.uniform(0.3, 0.7)), lz - 0.1),
    )


def _new_object(category: str, counts: dict[str, int], placed: list[_Placed], size, yaw, center, support, prims, joints) -> RoomObject:
    idx = counts.get(category, 0)
    return RoomObject(
        object_id=len(placed) + 1,
        name=f"{category}_{idx}",
        category=category,
        position_m=tuple(float(c) for c in center),
        size_m=tuple(float(s) for s in size),
        yaw_rad=float(np.arctan2(np.sin(yaw), np.cos(yaw))),
        support=support,
        primitives=tuple(prims),
        joints=tuple(joints),
    )


def _accept(obj: RoomObject, surfaces, placed: list[_Placed], counts: dict[str, int], host: str | None = None) -> bool:
    """Add ``obj`` unless one of its parts comes within 1 cm of a part of another object (its
    ``host``, the object it stands on, may touch it)."""
    boxes = _world_boxes(obj.primitives, obj.world_from_object, obj.yaw_rad)
    for p in placed:
        if _boxes_overlap(boxes, p.boxes, -0.002 if p.obj.name == host else 0.01):
            return False
    placed.append(_Placed(obj, boxes, list(surfaces)))
    counts[obj.category] = counts.get(obj.category, 0) + 1
    return True


def _try_floor(rng, category: str, placed: list[_Placed], counts, camera: Camera, walls: list[Wall], lx: float, ly: float) -> bool:
    size, prims, joints, surfaces = _build(category, rng)
    sx, sy, sz = size
    cam_xy = camera.position_m[:2]
    tables = [p for p in placed if p.obj.category == "table"]
    for _ in range(25):
        if category in _WALL_BACKED:
            wall = walls[rng.integers(len(walls))]
            n = np.array(wall.normal[:2])
            yaw = float(np.arctan2(n[1], n[0]) + rng.uniform(-0.08, 0.08))
            along = np.array([-n[1], n[0]])
            half = np.asarray(wall.center_m[:2])
            t = rng.uniform(-wall.half_length_m + 0.6, wall.half_length_m - 0.6)
            # Distance from the centre to the wall of the yawed footprint, plus a small gap.
            rel = yaw - np.arctan2(n[1], n[0])
            reach = abs(np.cos(rel)) * sx / 2 + abs(np.sin(rel)) * sy / 2
            xy = half + along * t + n * (reach + rng.uniform(0.01, 0.06))
        elif category == "chair" and tables and rng.random() < 0.7:
            tab = tables[rng.integers(len(tables))].obj
            side = rng.integers(4)
            local_dir = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]][side], dtype=np.float64)
            extent = (tab.size_m[0] if side < 2 else tab.size_m[1]) / 2
            r2 = frames.rot_z(tab.yaw_rad)[:2, :2]
            out = r2 @ local_dir
            xy = np.asarray(tab.position_m[:2]) + out * (extent + rng.uniform(0.0, 0.25)) + r2 @ np.array([-local_dir[1], local_dir[0]]) * rng.uniform(-0.2, 0.2)
            yaw = float(np.arctan2(-out[1], -out[0]) + rng.uniform(-0.3, 0.3))  # front (+X) faces the table
        else:
            xy = np.array([rng.uniform(0.4, lx - 0.4), rng.uniform(0.4, ly - 0.4)])
            yaw = float(rng.uniform(-np.pi, np.pi))
        if np.linalg.norm(xy - cam_xy) < 1.2:
            continue
        center = np.array([xy[0], xy[1], sz / 2])
        if not _visible_enough(camera, center, size, yaw):
            continue
        # Inside the room (walls are half-spaces): every footprint corner at least 1 cm in.
        corners = _box_corners(center, size, yaw)
        if np.any(corners[:, 0] > lx - 0.01) or np.any(corners[:, 1] > ly - 0.01) or np.any(corners[:, 1] < 0.01) or np.any(corners[:, 0] < 0.01):
            continue
        obj = _new_object(category, counts, placed, size, yaw, center, "floor", prims, joints)
        if _accept(obj, surfaces, placed, counts):
            return True
    return False


def _try_item(rng, category: str, host: _Placed, placed: list[_Placed], counts, camera: Camera) -> bool:
    size, prims, joints, surfaces = _build_item(category, rng)
    sx, sy, sz = size
    h = host.obj
    for _ in range(15):
        z_top, hx, hy, xc, clearance = host.surfaces[rng.integers(len(host.surfaces))]
        if sz > clearance - 0.01:
            continue
        yaw_local = float(rng.uniform(-np.pi, np.pi)) if category not in ("pillow", "laptop") else float(rng.uniform(-0.3, 0.3))
        rx = abs(np.cos(yaw_local)) * sx / 2 + abs(np.sin(yaw_local)) * sy / 2
        ry = abs(np.sin(yaw_local)) * sx / 2 + abs(np.cos(yaw_local)) * sy / 2
        if rx > hx or ry > hy:
            continue
        local = np.array([xc + rng.uniform(-hx + rx, hx - rx), rng.uniform(-hy + ry, hy - ry), z_top])
        bottom = frames.transform_points(h.world_from_object, local[None])[0]
        center = bottom + np.array([0.0, 0.0, sz / 2])
        yaw = h.yaw_rad + yaw_local
        if not _visible_enough(camera, center, size, yaw, min_in=4):
            continue
        obj = _new_object(category, counts, placed, size, yaw, center, h.name, prims, joints)
        if _accept(obj, surfaces, placed, counts, host=h.name):
            host.items += 1
            return True
    return False
