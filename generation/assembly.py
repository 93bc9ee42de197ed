"""Build an :class:`ObjectAsset` from part specifications: meshing, physics and collision.

This is the one place where geometry becomes a simulation-ready asset; the shape-prior
generator, the articulation templates and the PhysX VLM backend (``generation.physx``) all go
through :func:`assemble_asset`.

A part's geometry is one of

* :class:`VoxelGeometry`: a bool (X, Y, Z) occupancy grid, the voxel edge in metres and the grid
  origin (min corner of voxel (0, 0, 0)) in the asset frame: meshed by marching cubes,
  collision by splitting the voxels into convex pieces (or one hull when nearly convex);
* :class:`ConvexSolids`: closed convex solids (boxes, cylinders) whose union is the part: the
  visual mesh is their boolean union and the solids themselves are the collision pieces;
* a :class:`TriangleMesh` (or ``trimesh.Trimesh``): a watertight mesh used as is, collision by
  CoACD (or one hull).

Example (a voxel part from the PhysX decoder)::

    spec = PartSpec("door", parent="body", geometry=VoxelGeometry(occ, 0.01, origin),
                    material="particleboard",
                    joint=JointSpec(JointType.REVOLUTE, axis=(0, 0, -1), anchor_m=(0.3, -0.4, 0.0),
                                    lower=0.0, upper=1.7),
                    affordance_rank=1, affordance="pull handle to open")
    asset = assemble_asset("cabinet_1", "cabinet", [body_spec, spec])
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence, Union

import numpy as np

from scene_builder.config import GenerationConfig
from scene_builder.model import (
    AssetKind,
    DeformableSettings,
    Joint,
    JointType,
    Material,
    ObjectAsset,
    Part,
    TriangleMesh,
    as_array,
)

__all__ = [
    "ConvexSolids",
    "JointSpec",
    "PartSpec",
    "VoxelGeometry",
    "assemble_asset",
    "assemble_asset_with_offset",
    "box_solid",
]


@dataclass(frozen=True, eq=False)
class VoxelGeometry:
    """occupancy: (X, Y, Z) bool. voxel_size_m: voxel edge. origin_m: (3,) min corner of voxel
    (0, 0, 0) in the asset frame (voxel (i, j, k) spans origin + [i, i+1] * voxel_size_m ...)."""

    occupancy: np.ndarray
    voxel_size_m: float
    origin_m: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "occupancy", as_array(self.occupancy, np.bool_, (None, None, None), "VoxelGeometry.occupancy"))
        object.__setattr__(self, "origin_m", as_array(self.origin_m, np.float64, (3,), "VoxelGeometry.origin_m"))
        if not self.voxel_size_m > 0:
            raise ValueError(f"VoxelGeometry.voxel_size_m must be positive, got {self.voxel_size_m}")


@dataclass(frozen=True, eq=False)
class ConvexSolids:
    """solids: closed convex meshes (asset frame) whose union is the part; they are its collision
    pieces. visual: optional watertight mesh of the part when the union of the solids is only
    an approximation of it (e.g. a smooth revolved mug whose walls the solids tile); mass then
    comes from ``visual``."""

    solids: tuple[TriangleMesh, ...]
    visual: TriangleMesh | None = None

    def __post_init__(self) -> None:
        if not self.solids:
            raise ValueError("ConvexSolids needs at least one solid")


Geometry = Union[VoxelGeometry, ConvexSolids, TriangleMesh]


@dataclass(frozen=True, eq=False)
class JointSpec:
    """A joint to the parent part, asset frame at rest. Units as in :class:`Joint`.

    damping / friction / effort_limit: None = derived from the moving subtree's mass and size
    (``generation.physics.joint_resistance``).
    """

    type: JointType
    axis: tuple[float, float, float] | np.ndarray
    anchor_m: tuple[float, float, float] | np.ndarray
    lower: float = 0.0
    upper: float = 0.0
    lower2: float = 0.0
    upper2: float = 0.0
    damping: float | None = None
    friction: float | None = None
    effort_limit: float | None = None


@dataclass(frozen=True, eq=False)
class PartSpec:
    """What a part is made of, before meshing and physics.

    material: a :class:`Material` or a name from ``generation.materials.MATERIALS``.
    shell_thickness_m: wall thickness of a hollow part (mass from the walls only), None = solid.
    rgba: colour used for the vertices when no observed points are near (None: the material's).
    """

    name: str
    parent: str | None
    geometry: Geometry
    material: Material | str
    joint: JointSpec | None = None
    affordance_rank: int = 5
    affordance: str = ""
    description: str = ""
    shell_thickness_m: float | None = None
    rgba: tuple[float, float, float, float] | None = None


def box_solid(min_corner_m, max_corner_m) -> TriangleMesh:
    """Axis-aligned box between two corners, as a closed outward-facing :class:`TriangleMesh`."""
    lo = np.asarray(min_corner_m, dtype=np.float64)
    hi = np.asarray(max_corner_m, dtype=np.float64)
    if np.any(hi - lo <= 0):
        raise ValueError(f"box_solid: empty box {lo} .. {hi}")
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    faces = np.array(
        [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    )
    return TriangleMesh(corners, faces)


def _material(spec: PartSpec) -> Material:
    from generation.materials import material

    if isinstance(spec.material, Material):
        return spec.material
    return material(spec.material, spec.rgba)


#: Snapping a voxel part's surface onto the observed depth may change its volume by this share.
SNAP_MAX_VOLUME_CHANGE = 0.25


def _inertia_ok(mesh) -> bool:
    """Whether a closed mesh has positive volume and the inertia tensor of a body (positive
    definite is not enough: a surface folded over itself can give moments that break the
    triangle inequality, which MuJoCo rejects)."""
    from generation.physics import is_mass_distribution

    if not float(mesh.volume) > 0.0:
        return False
    return is_mass_distribution(np.asarray(mesh.moment_inertia, dtype=np.float64))


def _visual(spec: PartSpec, config: GenerationConfig):
    """(visual trimesh, convex solids as trimeshes or None)."""
    import trimesh

    from generation.meshing import check_watertight, decimate, mesh_from_occupancy, to_trimesh, union_of_solids

    g = spec.geometry
    if isinstance(g, VoxelGeometry):
        return mesh_from_occupancy(g.occupancy, g.voxel_size_m, g.origin_m, max_faces=config.max_visual_faces), None
    if isinstance(g, ConvexSolids):
        solids = [to_trimesh(s).copy() for s in g.solids]
        for s in solids:
            check_watertight(s, f"part {spec.name}: solid")
        if g.visual is not None:
            tm = to_trimesh(g.visual).copy()
            check_watertight(tm, f"part {spec.name}: visual")
            return decimate(tm, config.max_visual_faces), solids
        return union_of_solids(solids), solids
    if isinstance(g, (TriangleMesh, trimesh.Trimesh)):
        tm = to_trimesh(g).copy()
        tm.merge_vertices()
        check_watertight(tm, f"part {spec.name}")
        return decimate(tm, config.max_visual_faces), None
    raise TypeError(f"part {spec.name}: unsupported geometry {type(g).__name__}")


def _subtree(name: str, children: dict[str, list[str]]) -> list[str]:
    out, stack = [], [name]
    while stack:
        n = stack.pop()
        out.append(n)
        stack.extend(children.get(n, []))
    return out


def assemble_asset_with_offset(
    name: str,
    label: str,
    parts: Sequence[PartSpec],
    *,
    config: GenerationConfig | None = None,
    seed: int = 0,
    kind: AssetKind | None = None,
    is_fixed: bool | None = None,
    deformable: DeformableSettings | None = None,
    description: str = "",
    backend: str = "",
    observed_points_m: np.ndarray | None = None,
    observed_colors_rgb: np.ndarray | None = None,
    recenter: bool = True,
    surface_snap=None,
) -> tuple[ObjectAsset, np.ndarray]:
    """:func:`assemble_asset`, also returning the (3,) translation added to the input geometry
    (to put the asset-frame origin at the bottom-centre of the parts' bounding box).
    surface_snap: optional callable mapping (V, 3) vertices of a voxel part's visual mesh (input
    frame) to new positions, before mass properties are computed (``generation.visibility``
    moves the vertices the camera saw onto the observed depth)."""
    from generation.collision import _hull, _merge_smallest, convex_pieces, is_convex_enough, solid_piece, voxel_convex_pieces
    from generation.meshing import to_model_mesh, vertex_colors
    from generation.physics import combine_inertials, joint_resistance, mass_properties, shell_mass_properties
    from scene_builder.vocabulary import category

    config = config or GenerationConfig()
    if not parts:
        raise ValueError(f"assemble_asset {name}: no parts")
    names = [p.name for p in parts]
    if len(set(names)) != len(names):
        raise ValueError(f"assemble_asset {name}: duplicate part names {sorted(names)}")
    visuals, solids = [], []
    for spec in parts:
        v, s = _visual(spec, config)
        if surface_snap is not None and isinstance(spec.geometry, VoxelGeometry):
            # The marching-cubes surface lies up to a voxel off the observed one: its vertices
            # seen by the camera go onto the observed depth (positions only: still watertight).
            # A snap that folds the surface (volume lost, inertia no longer a body's: a thin
            # part seen edge-on, a lamp's shade) is not kept.
            before = np.array(v.vertices, dtype=np.float64)
            volume = float(v.volume)
            v.vertices = np.asarray(surface_snap(before))
            if not (abs(float(v.volume) - volume) <= SNAP_MAX_VOLUME_CHANGE * abs(volume) and _inertia_ok(v)):
                v.vertices = before
        visuals.append(v)
        solids.append(s)
    lo = np.min([v.bounds[0] for v in visuals], axis=0)
    hi = np.max([v.bounds[1] for v in visuals], axis=0)
    shift = np.zeros(3)
    if recenter:
        shift = -np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]])
        for v in visuals:
            v.apply_translation(shift)
        for s in solids:
            for piece in s or ():
                piece.apply_translation(shift)
    size = hi - lo

    pts = None if observed_points_m is None else np.asarray(observed_points_m, dtype=np.float64) + shift
    color_distance = 0.03 * float(np.max(size)) + 0.005

    inertials, materials, collisions, meshes = {}, {}, {}, {}
    for spec, v, s in zip(parts, visuals, solids):
        mat = _material(spec)
        materials[spec.name] = mat
        if spec.shell_thickness_m:
            inertials[spec.name] = shell_mass_properties(v, mat.density_kg_m3, spec.shell_thickness_m)
        else:
            inertials[spec.name] = mass_properties(v, mat.density_kg_m3)
        if s is not None:
            pieces = _merge_smallest([_hull(p.vertices) for p in s], config.max_collision_pieces)
        elif isinstance(spec.geometry, VoxelGeometry) and not is_convex_enough(v):
            # the grid is the shape: split its voxels directly (~0.1 s) instead of CoACD on the
            # marching-cubes surface (3-50 s per completed lamp on open3d_TUM)
            g = spec.geometry
            pieces = voxel_convex_pieces(g.occupancy, g.voxel_size_m, g.origin_m + shift, max_pieces=config.max_voxel_pieces)
        else:
            pieces = convex_pieces(
                v,
                threshold=config.coacd_threshold,
                max_pieces=config.max_collision_pieces,
                seed=seed,
                cache_dir=config.cache_dir,
            )
        if not pieces:  # a decomposition that found nothing: the part's hull
            pieces = [_hull(v.vertices)]
        collisions[spec.name] = tuple(to_model_mesh(solid_piece(p)) for p in pieces)
        fallback = np.round(np.asarray(spec.rgba or mat.rgba)[:3] * 255).astype(np.uint8)
        observed = pts is not None and observed_colors_rgb is not None
        # Far from observed points the root part takes the object's median observed colour, other
        # parts (doors, handles) their material's colour.
        colors = vertex_colors(
            v.vertices,
            pts if observed else None,
            observed_colors_rgb if observed else None,
            color_distance,
            None if observed and spec.parent is None else fallback,
        )
        meshes[spec.name] = to_model_mesh(v, colors)

    children: dict[str, list[str]] = {}
    for spec in parts:
        if spec.parent is not None:
            children.setdefault(spec.parent, []).append(spec.name)
    out_parts = []
    for spec in parts:
        joint = None
        if spec.joint is not None:
            js = spec.joint
            anchor = np.asarray(js.anchor_m, dtype=np.float64) + shift
            axis = np.asarray(js.axis, dtype=np.float64)
            axis = axis / np.linalg.norm(axis)
            moving = combine_inertials([inertials[n] for n in _subtree(spec.name, children)])
            res = joint_resistance(js.type, axis, anchor, moving, range_rad=(js.lower, js.upper))
            joint = Joint(
                type=js.type,
                axis=axis,
                anchor_m=anchor,
                lower=js.lower,
                upper=js.upper,
                damping=res.damping if js.damping is None else js.damping,
                friction=res.friction if js.friction is None else js.friction,
                effort_limit=res.effort_limit if js.effort_limit is None else js.effort_limit,
                lower2=js.lower2,
                upper2=js.upper2,
                stiffness=res.stiffness,
            )
        out_parts.append(
            Part(
                name=spec.name,
                parent=spec.parent,
                joint=joint,
                visual=meshes[spec.name],
                collision=collisions[spec.name],
                material=materials[spec.name],
                inertial=inertials[spec.name],
                affordance_rank=spec.affordance_rank,
                affordance=spec.affordance,
                description=spec.description,
            )
        )
    if kind is None:
        if deformable is not None:
            kind = AssetKind.DEFORMABLE
        elif any(p.joint is not None and p.joint.type is not JointType.FIXED for p in out_parts):
            kind = AssetKind.ARTICULATED
        else:
            kind = AssetKind.RIGID
    asset = ObjectAsset(
        name=name,
        label=label,
        kind=kind,
        parts=tuple(out_parts),
        size_m=size,
        description=description,
        is_fixed=category(label).fixed if is_fixed is None else is_fixed,
        deformable=deformable,
        backend=backend,
    )
    return asset, shift


def assemble_asset(
    name: str,
    label: str,
    parts: Sequence[PartSpec],
    *,
    config: GenerationConfig | None = None,
    seed: int = 0,
    kind: AssetKind | None = None,
    is_fixed: bool | None = None,
    deformable: DeformableSettings | None = None,
    description: str = "",
    backend: str = "",
    observed_points_m: np.ndarray | None = None,
    observed_colors_rgb: np.ndarray | None = None,
    recenter: bool = True,
) -> ObjectAsset:
    """Build a simulation-ready :class:`ObjectAsset` from part specifications.

    parts: one :class:`PartSpec` per part, exactly one with ``parent=None`` (the root); geometry
    and joints in one common frame (the asset frame: Z up, +X front). For each part: a watertight
    visual mesh (marching cubes for voxels, boolean union for convex solids), mass properties by
    exact integration (solid, or hollow walls when ``shell_thickness_m`` is set), convex
    collision pieces (the solids themselves, one hull, or CoACD with ``config`` and ``seed``),
    joint damping / friction derived from the moving subtree's mass unless given.
    kind: None = ARTICULATED when a non-fixed joint exists, DEFORMABLE when ``deformable`` is
    given, else RIGID. is_fixed: None = the category's default.
    observed_points_m: (N, 3) observed points in the same frame, with observed_colors_rgb (N, 3)
    uint8, to colour the vertices. recenter: translate everything so that the origin is the
    bottom-centre of the parts' bounding box, as the asset frame requires.
    """
    asset, _ = assemble_asset_with_offset(
        name,
        label,
        parts,
        config=config,
        seed=seed,
        kind=kind,
        is_fixed=is_fixed,
        deformable=deformable,
        description=description,
        backend=backend,
        observed_points_m=observed_points_m,
        observed_colors_rgb=observed_colors_rgb,
        recenter=recenter,
    )
    return asset
