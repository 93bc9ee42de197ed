"""The data model: frozen, typed dataclasses that every stage passes to the next.

Frames and units (the one place they are written down)
------------------------------------------------------
* **Units**: metres, kilograms, seconds, radians, pascals. Field names carry the unit
  (``depth_m``, ``mass_kg``, ``inertia_kg_m2``); unitless fields say so in their docstring.
* **World frame**: right-handed, **Z up** (against gravity), metres. The floor is the plane
  ``z = 0``. The X axis is the horizontal projection of the camera's optical axis unless the
  room's walls were found, in which case X and Y follow the dominant wall directions
  (Manhattan frame) closest to that projection.
* **Camera frame**: OpenCV. x right, y down, z forward along the optical axis, metres.
  Pixel ``(u, v)`` is column ``u``, row ``v``; integer coordinates are pixel centres, so the
  top-left pixel's centre is ``(0, 0)``. A point ``p_cam`` projects to
  ``u = fx * x / z + cx``, ``v = fy * y / z + cy``.
* **Asset frame**: each :class:`ObjectAsset` has its own frame, Z up, origin at the centre of
  the bottom face of the asset's axis-aligned bounding box, so an asset placed with the
  identity rotation at ``(x, y, 0)`` stands on the floor. The asset's **front** (the side seen
  in the photo, where doors and drawers open) faces **+X**.
* **Transforms** are 4x4 homogeneous float64 matrices named ``a_from_b``: they map a point
  expressed in frame ``b`` into frame ``a`` (``p_a = a_from_b @ [p_b, 1]``).
* **Depth** is planar z-depth (distance along the optical axis), not ray length. Invalid depth
  pixels hold ``0.0``.
* **Texture coordinates** ``uv`` follow the image: ``u`` runs right and ``v`` runs *down* from the
  top-left corner of the texture image, both in [0, 1]; the centre of pixel ``(x, y)`` of a
  ``W`` x ``H`` texture is ``((x + 0.5) / W, (y + 0.5) / H)`` (glTF's convention; USD's ``st``
  and OBJ's ``vt`` use ``1 - v``, and each exporter converts).

Arrays are stored read-only (``ndarray.flags.writeable`` is False) so that frozen really means
frozen; copy before modifying. Dataclasses that hold arrays compare by identity (``eq=False``).
"""

from __future__ import annotations

import enum
import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "AssetKind",
    "Background",
    "BackendUse",
    "Camera",
    "CameraIntrinsics",
    "DeformableSettings",
    "ExportedFiles",
    "Fidelity",
    "Front",
    "GeneratedAsset",
    "Inertial",
    "Joint",
    "JointProbe",
    "JointType",
    "LayoutResult",
    "Material",
    "ObjectAsset",
    "ObjectVerdict",
    "Observation",
    "Part",
    "PerceivedObject",
    "Perception",
    "PhysicsVerdict",
    "PlacedObject",
    "PushPlan",
    "PushResult",
    "Placement",
    "Plane",
    "RobotModel",
    "RobotPlacement",
    "Room",
    "Scene",
    "SupportEdge",
    "Texture",
    "Trajectory",
    "TriangleMesh",
    "as_array",
]


from scene_builder.arrays import MIN_PIECE_THICKNESS_M, _check_rigid, _freeze, as_array, inertia_problem, thickness_m  # noqa: E402  (as_array is public)
from scene_builder.robot import RobotModel, RobotPlacement  # noqa: E402  (re-exported)
from scene_builder.fronts import Front  # noqa: E402  (re-exported)
from scene_builder.planes import Plane  # noqa: E402  (re-exported)


# --------------------------------------------------------------------------------------------
# Camera and observation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of the input image, in pixels (OpenCV convention).

    ``source`` says where they came from: ``"flag"``, ``"file"`` (camera.json), ``"exif"``,
    ``"depth-model"``, ``"vanishing-points"`` or ``"default-fov"``.
    """

    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    width_px: int
    height_px: int
    source: str = "flag"

    def __post_init__(self) -> None:
        for name in ("fx_px", "fy_px"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"CameraIntrinsics.{name} must be a positive number, got {v}")
        for name in ("cx_px", "cy_px"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"CameraIntrinsics.{name} must be finite")
        if self.width_px <= 0 or self.height_px <= 0:
            raise ValueError("CameraIntrinsics: width_px and height_px must be positive")

    @property
    def matrix(self) -> np.ndarray:
        """(3, 3) float64 camera matrix K."""
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    @property
    def fovy_deg(self) -> float:
        """Vertical field of view in degrees."""
        return float(np.degrees(2.0 * np.arctan2(self.height_px / 2.0, self.fy_px)))

    @classmethod
    def from_fov(cls, width_px: int, height_px: int, fov_deg: float, source: str = "default-fov") -> "CameraIntrinsics":
        """Square-pixel intrinsics with horizontal field of view ``fov_deg`` and a centred principal point."""
        if not (0.0 < fov_deg < 180.0):
            raise ValueError(f"field of view must be between 0 and 180 degrees, got {fov_deg}")
        f = (width_px / 2.0) / np.tan(np.radians(fov_deg) / 2.0)
        return cls(float(f), float(f), (width_px - 1) / 2.0, (height_px - 1) / 2.0, int(width_px), int(height_px), source)

    def scaled(self, width_px: int, height_px: int) -> "CameraIntrinsics":
        """The same camera for an image resized to ``width_px`` x ``height_px``."""
        sx, sy = width_px / self.width_px, height_px / self.height_px
        return CameraIntrinsics(
            self.fx_px * sx,
            self.fy_px * sy,
            (self.cx_px + 0.5) * sx - 0.5,
            (self.cy_px + 0.5) * sy - 0.5,
            int(width_px),
            int(height_px),
            self.source,
        )

    def unproject(self, depth_m: np.ndarray) -> np.ndarray:
        """Back-project a depth image to camera-frame points.

        depth_m: (H, W) planar depth. Returns (H, W, 3) float64 points in the camera frame
        (invalid pixels, depth 0, map to the origin).
        """
        h, w = depth_m.shape
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        z = depth_m.astype(np.float64)
        return np.stack([(u - self.cx_px) * z / self.fx_px, (v - self.cy_px) * z / self.fy_px, z], axis=-1)

    def project(self, points_cam_m: np.ndarray) -> np.ndarray:
        """Project (N, 3) camera-frame points to (N, 2) pixel coordinates (u, v)."""
        p = np.asarray(points_cam_m, dtype=np.float64)
        z = p[:, 2]
        return np.stack([self.fx_px * p[:, 0] / z + self.cx_px, self.fy_px * p[:, 1] / z + self.cy_px], axis=-1)


@dataclass(frozen=True, eq=False)
class Camera:
    """The input camera: intrinsics and its pose in the world frame.

    world_from_camera: (4, 4) float64 rigid transform (camera frame is OpenCV).
    """

    intrinsics: CameraIntrinsics
    world_from_camera: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self, "world_from_camera", np.float64, (4, 4))
        _check_rigid(self.world_from_camera, "Camera.world_from_camera")

    @property
    def position_m(self) -> np.ndarray:
        """(3,) camera centre in the world frame."""
        return self.world_from_camera[:3, 3].copy()


@dataclass(frozen=True)
class BackendUse:
    """Which backend answered one task, and why (recorded in report.json).

    task: ``"depth"``, ``"segmentation"``, ``"naming"``, ``"intrinsics"``, ``"generation"`` ...
    backend: registry name of the backend that answered.
    reason: one line: why this backend (e.g. "sensor depth given", "weights for
    depth-anything-v2-small not found in models dir; using geometric single-view depth").
    """

    task: str
    backend: str
    reason: str


@dataclass(frozen=True, eq=False)
class Observation:
    """What the camera saw, as loaded and checked.

    rgb: (H, W, 3) uint8, EXIF orientation already applied, at the analysis resolution that the
      depth, the intrinsics and every object mask share (a large photo is downscaled for analysis).
    depth_m: (H, W) float32 planar depth in metres, 0.0 where invalid. Either from a sensor
      (``depth_source == "sensor"``) or estimated (``depth_source`` names the backend).
    rgb_full: (H', W', 3) uint8, the photo at its stored resolution when it was downscaled for
      analysis (the same view: intrinsics scale by W' / W), for textures; None when rgb is it.
    """

    image_path: str
    rgb: np.ndarray
    depth_m: np.ndarray
    intrinsics: CameraIntrinsics
    depth_source: str
    rgb_full: np.ndarray | None = None

    @property
    def photo_rgb(self) -> np.ndarray:
        """(H', W', 3) uint8: the photo at full resolution (``rgb_full``, else ``rgb``)."""
        return self.rgb if self.rgb_full is None else self.rgb_full

    def __post_init__(self) -> None:
        _freeze(self, "rgb", np.uint8, (None, None, 3))
        if self.rgb_full is not None:
            _freeze(self, "rgb_full", np.uint8, (None, None, 3))
            fh, fw = self.rgb_full.shape[:2]
            h, w = self.rgb.shape[:2]
            if abs(fw / fh - w / h) > 0.02 * (w / h):
                raise ValueError("Observation.rgb_full: aspect ratio differs from rgb's (not the same view)")
        _freeze(self, "depth_m", np.float32, self.rgb.shape[:2])
        if float(self.depth_m.min(initial=0.0)) < 0.0:
            raise ValueError("Observation.depth_m: negative depth")
        if (self.intrinsics.width_px, self.intrinsics.height_px) != (self.rgb.shape[1], self.rgb.shape[0]):
            raise ValueError("Observation: intrinsics size does not match the image size")

    @property
    def valid_depth(self) -> np.ndarray:
        """(H, W) bool, True where depth was measured."""
        return self.depth_m > 0.0


# --------------------------------------------------------------------------------------------
# Perception
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Texture:
    """An RGB image that meshes map onto their surface through ``TriangleMesh.uv``.

    name: unique in the scene and safe as a file name (exporters write ``textures/<name>.png``).
    image_rgb: (H, W, 3) uint8.
    """

    name: str
    image_rgb: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self, "image_rgb", np.uint8, (None, None, 3))
        if self.image_rgb.shape[0] == 0 or self.image_rgb.shape[1] == 0:
            raise ValueError(f"Texture {self.name}: empty image")
        if not self.name or any(c in self.name for c in "/\\\0") or self.name in (".", ".."):
            raise ValueError(f"Texture name {self.name!r} is not a safe file name")

    @functools.cached_property
    def png_bytes(self) -> bytes:
        """The image as PNG at zlib level 1 (the same bytes for the same image), encoded once:
        the exporters' ``textures/<name>.png`` and ``scene.json`` carry these bytes."""
        import io

        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(np.ascontiguousarray(self.image_rgb)).save(buf, format="PNG", compress_level=1)
        return buf.getvalue()


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """A triangle mesh.

    vertices_m: (V, 3) float64.
    faces: (F, 3) int64 vertex indices, counter-clockwise seen from outside.
    vertex_colors_rgba: (V, 4) uint8, or None.
    uv: (V, 2) float64 texture coordinates of each vertex in ``texture`` (see the module
      docstring for the convention), or None. Given together with ``texture`` or not at all.
    """

    vertices_m: np.ndarray
    faces: np.ndarray
    vertex_colors_rgba: np.ndarray | None = None
    uv: np.ndarray | None = None
    texture: Texture | None = None

    def __post_init__(self) -> None:
        _freeze(self, "vertices_m", np.float64, (None, 3))
        _freeze(self, "faces", np.int64, (None, 3))
        if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= len(self.vertices_m)):
            raise ValueError("TriangleMesh.faces: index out of range")
        if self.vertex_colors_rgba is not None:
            _freeze(self, "vertex_colors_rgba", np.uint8, (len(self.vertices_m), 4))
        if (self.uv is None) != (self.texture is None):
            raise ValueError("TriangleMesh: uv and texture go together")
        if self.uv is not None:
            _freeze(self, "uv", np.float64, (len(self.vertices_m), 2))

    @property
    def bounds_m(self) -> np.ndarray:
        """(2, 3) float64: min and max corner."""
        return np.stack([self.vertices_m.min(axis=0), self.vertices_m.max(axis=0)])


@dataclass(frozen=True, eq=False)
class Background:
    """What was observed but is not a movable object: one static, textured body in the world frame
    (floor, walls, ceiling, counters, shelves, built-ins, clutter), never moved by physics.

    surface: the observed depth map as a mesh in the world frame, textured with the photo (the
      pixels of movable objects are filled in behind them: floor and wall planes extended,
      depth inpainted elsewhere; their colour inpainted from the surroundings).
    surface_observed: (V,) bool per ``surface`` vertex, True where its depth was measured or
      estimated for that pixel (False: filled in behind an object or in a depth hole).
    static_meshes: visual meshes (world frame) of objects that could not stand physically where
      they were seen and became part of the background; ``static_names`` are their object names.
    static_pieces: convex collision pieces (world frame) of those objects.
    box_centers_m: (B, 3), box_half_extents_m: (B, 3) and box_yaws_rad: (B,) collision boxes
      (yaw about +Z): the voxelised observed surface and the pads seen under objects.
    closed_sides: how many sides of the room box no wall was seen on were closed by a wall in
      ``surface`` (``perception.room_surfaces.closing_walls``: a guess, drawn only, no collision).
    """

    surface: TriangleMesh
    surface_observed: np.ndarray
    static_meshes: tuple[TriangleMesh, ...] = ()
    static_names: tuple[str, ...] = ()
    static_pieces: tuple[TriangleMesh, ...] = ()
    box_centers_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    box_half_extents_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    box_yaws_rad: np.ndarray = field(default_factory=lambda: np.zeros((0,)))
    closed_sides: int = 0

    def __post_init__(self) -> None:
        _freeze(self, "surface_observed", np.bool_, (len(self.surface.vertices_m),))
        _freeze(self, "box_centers_m", np.float64, (None, 3))
        n = len(self.box_centers_m)
        _freeze(self, "box_half_extents_m", np.float64, (n, 3))
        _freeze(self, "box_yaws_rad", np.float64, (n,))
        if n and float(self.box_half_extents_m.min()) <= 0.0:
            raise ValueError("Background: box half extents must be positive")
        if len(self.static_meshes) != len(self.static_names):
            raise ValueError("Background: one name per static mesh")

    @property
    def box_count(self) -> int:
        return int(len(self.box_centers_m))


@dataclass(frozen=True, eq=False)
class Room:
    """The room's fixed geometry in the world frame: the floor is always ``z = 0``.

    walls: vertical planes found in the observation, normals pointing into the room.
    background: the static, textured observed geometry (None when not built).
    """

    walls: tuple[Plane, ...] = ()
    background: Background | None = None


@dataclass(frozen=True, eq=False)
class PerceivedObject:
    """One object instance seen in the photo.

    object_id: 1-based instance id, unique in the observation.
    name: unique, readable identifier (``"chair_2"``), safe for file and prim names.
    label: category from the project vocabulary, ``"object"`` when unknown.
    label_confidence: in [0, 1].
    mask: (H, W) bool, True on the object's pixels; no pixel belongs to two objects.
    points_world_m: (N, 3) float64 observed surface points in the world frame (N >= 1).
    colors_rgb: (N, 3) uint8 colour of each point.
    fronts: the door and drawer fronts seen on its face (``perception.fronts``); generation
      makes each a moving part instead of a category template's (empty: none seen).
    built_in: fitted furniture (a kitchen run, a fitted wardrobe) found from its fronts rather
      than detected: welded to the room (``ObjectAsset.is_fixed``) whatever its label's default.
    """

    object_id: int
    name: str
    label: str
    label_confidence: float
    mask: np.ndarray
    points_world_m: np.ndarray
    colors_rgb: np.ndarray
    fronts: tuple[Front, ...] = ()
    built_in: bool = False

    def __post_init__(self) -> None:
        _freeze(self, "mask", np.bool_, (None, None))
        _freeze(self, "points_world_m", np.float64, (None, 3))
        _freeze(self, "colors_rgb", np.uint8, (self.points_world_m.shape[0], 3))
        if not 0.0 <= self.label_confidence <= 1.0:
            raise ValueError("PerceivedObject.label_confidence must be in [0, 1]")


@dataclass(frozen=True, eq=False)
class Perception:
    """Everything perception found: the observation, the gravity-aligned camera, room and objects.

    removed_mask: None, or (H, W) bool pixels of people and animals seen in the photo: not part of
    the room, in no object, filled in the background with what they hid.
    left_out_behind_walls / left_out_unmeasured: how many of the segmenter's instances were left
    out for lying mostly behind a wall (the next room, or past a wall's end) / for too few measured
    depth points to build (dark or far furniture): not in ``objects``, counted for the reports."""

    observation: Observation
    camera: Camera
    room: Room
    objects: tuple[PerceivedObject, ...]
    backends: tuple[BackendUse, ...] = ()
    removed_mask: np.ndarray | None = None
    left_out_behind_walls: int = 0
    left_out_unmeasured: int = 0

    def __post_init__(self) -> None:
        if self.removed_mask is not None:
            _freeze(self, "removed_mask", np.bool_, self.observation.rgb.shape[:2])


# --------------------------------------------------------------------------------------------
# Assets
# --------------------------------------------------------------------------------------------


class AssetKind(str, enum.Enum):
    """How an asset moves: one rigid body, a tree of jointed parts, or a soft body."""

    RIGID = "rigid"
    ARTICULATED = "articulated"
    DEFORMABLE = "deformable"


class JointType(str, enum.Enum):
    """Joint between a part and its parent (PhysX-Omni's movement types)."""

    FIXED = "fixed"
    REVOLUTE = "revolute"
    PRISMATIC = "prismatic"
    REVOLUTE_PRISMATIC = "revolute_prismatic"
    BALL = "ball"
    FREE = "free"


@dataclass(frozen=True)
class Material:
    """Physical and visual material of a part.

    density_kg_m3, static_friction and dynamic_friction (unitless Coulomb coefficients),
    restitution (unitless, 0..1), youngs_modulus_pa, poisson_ratio (unitless, 0..0.5).
    rgba: base colour, each channel in [0, 1]. source: where the numbers come from.
    """

    name: str
    density_kg_m3: float
    static_friction: float
    dynamic_friction: float
    restitution: float
    youngs_modulus_pa: float
    poisson_ratio: float
    rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0)
    source: str = ""

    def __post_init__(self) -> None:
        if not self.density_kg_m3 > 0:
            raise ValueError(f"Material {self.name}: density must be positive")
        if not (0 <= self.dynamic_friction <= self.static_friction):
            raise ValueError(f"Material {self.name}: need 0 <= dynamic_friction <= static_friction")
        if not 0 <= self.restitution <= 1:
            raise ValueError(f"Material {self.name}: restitution must be in [0, 1]")
        if not 0 <= self.poisson_ratio <= 0.5:
            raise ValueError(f"Material {self.name}: Poisson's ratio must be in [0, 0.5]")


@dataclass(frozen=True, eq=False)
class Inertial:
    """Mass properties of a part, computed from its geometry and material.

    mass_kg: > 0.
    com_m: (3,) centre of mass in the asset frame.
    inertia_kg_m2: (3, 3) symmetric positive-definite inertia tensor about the centre of mass,
      axes of the asset frame, whose principal moments satisfy the triangle inequality with a
      margin (``scene_builder.arrays.inertia_problem``: every exporter's consumer accepts it).
    """

    mass_kg: float
    com_m: np.ndarray
    inertia_kg_m2: np.ndarray

    def __post_init__(self) -> None:
        if not (np.isfinite(self.mass_kg) and self.mass_kg > 0):
            raise ValueError(f"Inertial.mass_kg must be positive, got {self.mass_kg}")
        _freeze(self, "com_m", np.float64, (3,))
        _freeze(self, "inertia_kg_m2", np.float64, (3, 3))
        problem = inertia_problem(self.inertia_kg_m2)  # a mass distribution's (what MuJoCo accepts)
        if problem:
            raise ValueError(f"Inertial.inertia_kg_m2 {problem}")

    def principal(self) -> tuple[np.ndarray, np.ndarray]:
        """Principal moments (3,) ascending and rotation (3, 3) whose columns are the principal axes
        (a proper rotation, det +1), so ``inertia = R @ diag(moments) @ R.T``."""
        moments, axes = np.linalg.eigh(self.inertia_kg_m2)
        if np.linalg.det(axes) < 0:
            axes[:, 2] *= -1.0
        return moments, axes


@dataclass(frozen=True, eq=False)
class Joint:
    """The joint that attaches a part to its parent part.

    axis: (3,) unit vector in the asset frame (rest pose).
    anchor_m: (3,) a point on the joint axis in the asset frame (hinge line, slide origin).
    lower, upper: limits of the joint's first degree of freedom, radians for revolute, metres
      for prismatic (0 = rest pose as modelled). For ``REVOLUTE_PRISMATIC`` the slide along the
      same axis uses ``lower2``, ``upper2`` (metres). Ignored for fixed, ball and free joints.
    damping: N*m*s/rad (revolute) or N*s/m (prismatic). friction: N*m or N (dry friction loss).
    effort_limit: N*m or N. stiffness: N*m/rad, a spring pulling the joint toward its rest pose
    (0 = none): the counterbalance of a door hinged at its bottom
    (``generation.physics.joint_resistance``).
    """

    type: JointType
    axis: np.ndarray
    anchor_m: np.ndarray
    lower: float = 0.0
    upper: float = 0.0
    damping: float = 0.0
    friction: float = 0.0
    effort_limit: float = 0.0
    lower2: float = 0.0
    upper2: float = 0.0
    stiffness: float = 0.0

    def __post_init__(self) -> None:
        _freeze(self, "axis", np.float64, (3,))
        _freeze(self, "anchor_m", np.float64, (3,))
        if not np.isclose(np.linalg.norm(self.axis), 1.0, atol=1e-6):
            raise ValueError("Joint.axis must be a unit vector")
        if self.lower > self.upper or self.lower2 > self.upper2:
            raise ValueError("Joint: lower limit above upper limit")
        if self.damping < 0 or self.friction < 0 or self.effort_limit < 0 or self.stiffness < 0:
            raise ValueError("Joint: damping, friction, effort_limit and stiffness must be >= 0")


@dataclass(frozen=True, eq=False)
class Part:
    """One rigid part of an asset, modelled at the asset's rest pose in the asset frame.

    parent: name of the parent part, None for the root part (exactly one per asset).
    joint: joint to the parent, None for the root.
    visual: watertight visual mesh in the asset frame (closed by position: a textured one is split
      at its texture seams, one vertex per position and texture coordinate).
    collision: convex pieces (each a closed convex mesh, a solid ``MIN_PIECE_THICKNESS_M`` thick or
      more) in the asset frame; at least one.
    affordance_rank: 1..10, 1 = most likely to be touched or grasped (PhysX convention).
    affordance: short verb phrase ("pull handle to open", "sit", "place objects on top").
    """

    name: str
    parent: str | None
    joint: Joint | None
    visual: TriangleMesh
    collision: tuple[TriangleMesh, ...]
    material: Material
    inertial: Inertial
    affordance_rank: int = 5
    affordance: str = ""
    description: str = ""

    def __post_init__(self) -> None:
        if (self.parent is None) != (self.joint is None):
            raise ValueError(f"Part {self.name}: the root part has no joint; every other part has one")
        if not self.collision:
            raise ValueError(f"Part {self.name}: needs at least one collision piece")
        for k, piece in enumerate(self.collision):
            if thickness_m(piece.vertices_m) < MIN_PIECE_THICKNESS_M:
                raise ValueError(f"Part {self.name}: collision piece {k} is flat or tiny; each must be a solid {MIN_PIECE_THICKNESS_M * 1000:g} mm thick or more")
        if not 1 <= self.affordance_rank <= 10:
            raise ValueError(f"Part {self.name}: affordance_rank must be in 1..10")


@dataclass(frozen=True)
class DeformableSettings:
    """Soft-body parameters (exported as a MuJoCo flex / UsdPhysics deformable).

    youngs_modulus_pa, poisson_ratio (unitless), damping (unitless Rayleigh-style ratio as used by
    MuJoCo flex elasticity), thickness_m (for shells), resolution (unitless: nodes per axis of the
    simulation grid).
    """

    youngs_modulus_pa: float
    poisson_ratio: float
    damping: float
    thickness_m: float = 0.0
    resolution: int = 4


@dataclass(frozen=True, eq=False)
class ObjectAsset:
    """A simulation-ready object in the PhysX-Omni sense: a tree of parts with geometry, absolute
    scale, materials, kinematics or deformation, affordances and a description.

    name: unique in the scene. label: category from the project vocabulary.
    size_m: (3,) extents of the axis-aligned bounding box of all parts, asset frame.
    is_fixed: welded to the world (built-in furniture) instead of a free body.
    backend: registry name of the generator that made it.
    fallback_reason: when the preferred generator failed on this object and ``backend`` answered
    instead, why (one line); empty otherwise.
    observed_shape: its geometry was built from the observed surface (extruded, completed and
      carved at the pose where it was seen), not fitted from a prior: its yaw is the
      observation's, so the layout never turns it.
    """

    name: str
    label: str
    kind: AssetKind
    parts: tuple[Part, ...]
    size_m: np.ndarray
    description: str = ""
    is_fixed: bool = False
    deformable: DeformableSettings | None = None
    backend: str = ""
    fallback_reason: str = ""
    observed_shape: bool = False

    def __post_init__(self) -> None:
        _freeze(self, "size_m", np.float64, (3,))
        roots = [p for p in self.parts if p.parent is None]
        if len(roots) != 1:
            raise ValueError(f"ObjectAsset {self.name}: needs exactly one root part, has {len(roots)}")
        names = [p.name for p in self.parts]
        if len(set(names)) != len(names):
            raise ValueError(f"ObjectAsset {self.name}: part names must be unique")
        for p in self.parts:
            if p.parent is not None and p.parent not in names:
                raise ValueError(f"ObjectAsset {self.name}: part {p.name} has unknown parent {p.parent}")
        if (self.kind is AssetKind.DEFORMABLE) != (self.deformable is not None):
            raise ValueError(f"ObjectAsset {self.name}: deformable settings go with kind DEFORMABLE only")

    @property
    def root(self) -> Part:
        return next(p for p in self.parts if p.parent is None)

    @property
    def mass_kg(self) -> float:
        return float(sum(p.inertial.mass_kg for p in self.parts))


@dataclass(frozen=True, eq=False)
class GeneratedAsset:
    """What the generator hands the layout solver: an asset and the pose at which it best explains
    the observed points (gravity-aligned: rotation about Z only; bottom at the observed support).

    world_from_asset: (4, 4) float64 rigid transform, the solver's starting point.
    observed_points_world_m: (N, 3) float64, the object's observed points (for the solver's
      data term: they should lie on the asset's surface).
    """

    asset: ObjectAsset
    world_from_asset: np.ndarray
    observed_points_world_m: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self, "world_from_asset", np.float64, (4, 4))
        _check_rigid(self.world_from_asset, f"GeneratedAsset {self.asset.name}.world_from_asset")
        _freeze(self, "observed_points_world_m", np.float64, (None, 3))


# --------------------------------------------------------------------------------------------
# Layout and scene
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PlacedObject:
    """An asset placed in the world.

    world_from_asset: (4, 4) float64 rigid transform.
    support: what it rests on: ``"floor"``, ``"wall"`` or the name of another object.
    """

    asset: ObjectAsset
    world_from_asset: np.ndarray
    support: str = "floor"

    def __post_init__(self) -> None:
        _freeze(self, "world_from_asset", np.float64, (4, 4))
        _check_rigid(self.world_from_asset, f"PlacedObject {self.asset.name}.world_from_asset")

    @property
    def name(self) -> str:
        return self.asset.name


@dataclass(frozen=True, eq=False)
class Scene:
    """The simulation-ready scene: camera, room and placed objects, in the world frame."""

    camera: Camera
    room: Room
    objects: tuple[PlacedObject, ...]
    robot: RobotPlacement | None = None  # ``--robot``: attached by the exporters as ``robot/``

    def __post_init__(self) -> None:
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            raise ValueError("Scene: object names must be unique")

    def object(self, name: str) -> PlacedObject:
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(name)


@dataclass(frozen=True)
class SupportEdge:
    """``child`` rests on ``parent`` (``"floor"``, ``"background"``, ``"wall"`` or an object name)."""

    child: str
    parent: str
    contact_gap_m: float = 0.0


@dataclass(frozen=True)
class Placement:
    """How the layout placed one perceived object, against where it was seen.

    displacement_m: distance from the observed asset origin (generation's fit to the observed
      points) to the placed one. yaw_change_deg: absolute change of yaw (snapping to the walls).
    support: what it rests on: ``"floor"``, ``"background"`` (static geometry seen under it),
      ``"wall"`` or the name of another object.
    became_background: it could not stand physically where it was seen and is now part of the
      static background (``Room.background.static_names``).
    reason: one line saying why it moved more than a centimetre or became background ("" when
      neither). lowered_m: how far it ended below where it was seen (negative: raised).
    """

    name: str
    displacement_m: float
    yaw_change_deg: float
    support: str
    became_background: bool = False
    reason: str = ""
    lowered_m: float = 0.0


@dataclass(frozen=True)
class LayoutResult:
    """Output of the layout solver. placements: one per generated asset, input order."""

    scene: Scene
    support: tuple[SupportEdge, ...]
    iterations: int = 0
    max_penetration_before_m: float = 0.0
    max_penetration_after_m: float = 0.0
    placements: tuple[Placement, ...] = ()


@dataclass(frozen=True)
class ExportedFiles:
    """Paths of the files the exporters wrote (None for a format that was switched off).
    urdf: the scene as one URDF (scene.urdf); object_urdfs: the folder of per-object URDFs."""

    mjcf: Path | None = None
    usd: Path | None = None
    urdf: Path | None = None
    gltf: Path | None = None
    rerun: Path | None = None
    sdf: Path | None = None
    object_urdfs: Path | None = None


# The results of the physics check and render-and-compare live in scene_builder.checks (to keep
# this module readable); they are part of the data model and re-exported here.
from scene_builder.checks import Fidelity, JointProbe, ObjectVerdict, PhysicsVerdict, PushPlan, PushResult, Trajectory  # noqa: E402
