"""From PhysX model text (overall description + per-part voxel tokens) to part specifications in
the asset frame, and from those to an :class:`~scene_builder.model.ObjectAsset`.

:func:`physx_object` is pure numpy: it decodes nothing itself, it takes the parsed description and
each part's (G, G, G) grid, fits the grid frame to the stated size (all three dimensions), turns
the grids into the asset frame's axes (front +x), fills closed shells (the PhysX voxels come from
surface samples, so a door panel is a hollow box of voxels; an open container stays open), gives
each part its material in SI units and its joint in metres / radians.

:func:`to_object_asset` meshes, decomposes and weighs the parts with the generator's
``generation.assemble.assemble_asset`` (the other half of ``generation/``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from scene_builder.errors import InputError
from scene_builder.model import Joint, JointType, Material, ObjectAsset

from generation.physx.description import PhysxDescription, ProtocolError
from generation.physx.grid_frame import GridFrame, group_joint
from generation.physx.tokens import decode_omni, decode_omni_lenient, decode_ranges, decode_ranges_lenient

__all__ = ["PhysxObject", "PhysxPartSpec", "decode_part_tokens", "model_size_m", "physx_object", "to_object_asset"]

# PhysX material words -> rows of the generator's material table (which supplies friction and
# restitution; PhysX gives density, Young's modulus and Poisson's ratio itself).
_MATERIAL_WORDS: tuple[tuple[str, str], ...] = (
    ("rubber", "rubber"),
    ("steel", "steel"),
    ("iron", "steel"),
    ("metal", "steel"),
    ("alumin", "aluminium"),
    ("glass", "glass"),
    ("ceramic", "ceramic"),
    ("porcelain", "ceramic"),
    ("stone", "stone"),
    ("marble", "stone"),
    ("granite", "stone"),
    ("particle", "particleboard"),
    ("mdf", "particleboard"),
    ("wood", "wood"),
    ("oak", "wood"),
    ("pine", "wood"),
    ("polypropylene", "plastic_pp"),
    ("(pp)", "plastic_pp"),
    ("pet", "plastic_pet"),
    ("plastic", "plastic_abs"),
    ("polymer", "plastic_abs"),
    ("hdpe", "plastic_pp"),
    ("leather", "leather"),
    ("foam", "foam"),
    ("fabric", "fabric"),
    ("cloth", "fabric"),
    ("cotton", "fabric"),
    ("cardboard", "cardboard"),
    ("paper", "paper"),
)


@dataclass(frozen=True, eq=False)
class PhysxPartSpec:
    """One rigid part, ready for meshing, in the asset frame.

    occupancy: (X, Y, Z) bool along the asset frame's axes (cropped to the object's box).
    voxel_size_m: (3,) voxel edge along asset x, y, z (equal unless the stated size asked for
      per-axis scales). origin_m: (3,) asset-frame min corner of voxel (0, 0, 0).
    parent: name of the parent part (None for the root); joint: asset-frame joint to it.
    material: SI numbers (density, Young's modulus, Poisson's ratio from the model; friction and
      restitution from the material table row its material name maps to).
    """

    label: int
    name: str
    parent: str | None
    joint: Joint | None
    occupancy: np.ndarray
    voxel_size_m: np.ndarray
    origin_m: np.ndarray
    material: Material
    affordance_rank: int
    description: str
    filled_voxels: int = 0

    def __post_init__(self) -> None:
        occ = np.array(self.occupancy, dtype=bool)
        if occ.ndim != 3:
            raise ValueError(f"PhysxPartSpec {self.name}: occupancy must be (X, Y, Z)")
        occ.setflags(write=False)
        object.__setattr__(self, "occupancy", occ)
        for name in ("voxel_size_m", "origin_m"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            if arr.shape != (3,):
                raise ValueError(f"PhysxPartSpec.{name} must have shape (3,)")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if (self.parent is None) != (self.joint is None):
            raise ValueError(f"PhysxPartSpec {self.name}: the root has no joint; every other part has one")

    @property
    def voxel_count(self) -> int:
        return int(self.occupancy.sum())

    @property
    def volume_m3(self) -> float:
        """Voxel volume (after filling closed shells)."""
        return self.voxel_count * float(np.prod(self.voxel_size_m))

    def voxel_centres_m(self) -> np.ndarray:
        """(N, 3) asset-frame centres of the occupied voxels."""
        return self.origin_m + (np.argwhere(self.occupancy) + 0.5) * self.voxel_size_m


@dataclass(frozen=True, eq=False)
class PhysxObject:
    """A PhysX description with geometry, in the asset frame. size_m: (3,) box of all parts
    (after the scale reconciliation when a target size was given). scale_to_target: (3,) the
    per-axis factors (asset x, y, z) applied to the model's own metric size to reach the target
    size (ones when there was no target)."""

    name: str
    category: str
    kind_articulated: bool
    size_m: np.ndarray
    parts: tuple[PhysxPartSpec, ...]
    frame: GridFrame
    description: PhysxDescription
    warnings: tuple[str, ...] = ()
    scale_to_target: np.ndarray = field(default_factory=lambda: np.ones(3))

    def part(self, name: str) -> PhysxPartSpec:
        for p in self.parts:
            if p.name == name:
                return p
        raise KeyError(name)

    @property
    def voxel_mass_kg(self) -> float:
        """Sum of density x voxel volume (the mesh-based mass of the assembled asset is close)."""
        return float(sum(p.material.density_kg_m3 * p.volume_m3 for p in self.parts))


def decode_part_tokens(text: str, grid: int, strict: bool = False) -> tuple[np.ndarray, tuple[str, ...]]:
    """Decode one part's geometry answer: range tokens for grid 32, template RLE otherwise.
    strict: raise TokenFormatError on any deviation; else repair and list the repairs."""
    if grid == 32:
        return (decode_ranges(text, grid), ()) if strict else decode_ranges_lenient(text, grid)
    return (decode_omni(text, grid), ()) if strict else decode_omni_lenient(text, grid)


def _slug(text: str, fallback: str) -> str:
    s = re.sub(r"[^0-9a-z]+", "_", text.lower()).strip("_")
    return s or fallback


def _material(part, warnings: list[str]) -> Material:
    from generation.materials import MATERIALS

    text = part.material.lower()
    row_name = next((row for word, row in _MATERIAL_WORDS if word in text), None)
    row = MATERIALS.get(row_name) if row_name else None
    if row is None:
        row = MATERIALS["plastic_abs"] if "plastic_abs" in MATERIALS else next(iter(MATERIALS.values()))
        warnings.append(f"l_{part.label}: material {part.material!r} not in the table, friction of {row.name} used")
    density = part.density_kg_m3
    if density is None:
        density = row.density_kg_m3
        warnings.append(f"l_{part.label}: no density, {row.name} density {density:g} kg/m^3 used")
    young = part.youngs_modulus_pa if part.youngs_modulus_pa is not None else row.youngs_modulus_pa
    poisson = part.poisson_ratio if part.poisson_ratio is not None else row.poisson_ratio
    return Material(
        name=part.material or row.name,
        density_kg_m3=float(density),
        static_friction=row.static_friction,
        dynamic_friction=row.dynamic_friction,
        restitution=row.restitution,
        youngs_modulus_pa=float(young),
        poisson_ratio=float(min(max(poisson, 0.0), 0.49)),
        rgba=row.rgba,
        source=f"PhysX model output (density, Young's modulus, Poisson's ratio); friction from table row {row.name}",
    )


def model_size_m(description: PhysxDescription, part_grids: Mapping[int, np.ndarray]) -> np.ndarray:
    """(3,) asset-frame extents (x front-back, y width, z height) of the model's own answer: its
    Dimension fitted to the union of its parts' voxels as :func:`physx_object` does, in metres; in
    voxel units when the description states no Dimension (the proportions still hold). Raises
    ProtocolError when no part has a voxel."""
    union = np.zeros((description.grid,) * 3, dtype=bool)
    for p in description.parts:
        occ = part_grids.get(p.label)
        if occ is not None:
            union |= np.asarray(occ, dtype=bool)
    if not union.any():
        raise ProtocolError(f"PhysX object {description.name!r}: no part has any voxel")
    idx = np.argwhere(union)
    lo, hi = idx.min(axis=0), idx.max(axis=0)
    n = (hi - lo + 1.0)[[1, 0, 2]]
    if description.dimension_cm is None:
        return n
    frame, _ = GridFrame.from_dimension(description.dimension_cm, description.grid, (lo, hi))
    return n * frame.metres_per_voxel[[1, 0, 2]]


def physx_object(
    description: PhysxDescription,
    part_grids: Mapping[int, np.ndarray],
    fill_closed_shells: bool = True,
    max_anisotropy: float = 0.25,
    target_size_m: np.ndarray | None = None,
    max_target_anisotropy: float = 3.0,
) -> PhysxObject:
    """Part specifications in the asset frame from a description and each part's grid.

    part_grids: PhysX part label -> (G, G, G) bool ``[x, y, z]`` in the PhysX grid. Parts without
    voxels are dropped (with a warning); a group whose parts are all gone passes its children to
    its parent. target_size_m: (3,) asset-frame extents (x front-back, y width, z height) the
    object must have, e.g. the observed box: every part's voxels, joint anchors and slide ranges
    are scaled per axis so that the union of the parts spans exactly that box (all three axes,
    not the largest one alone). Raises ProtocolError when nothing of the base group has voxels or
    when the target's proportions differ from the model's by more than ``max_target_anisotropy``
    (largest over smallest per-axis factor: the model described another shape), InputError when
    the description has no Dimension and no target gives the metric scale.
    """
    from scipy import ndimage

    g_side = description.grid
    warnings: list[str] = []
    if description.dimension_cm is None:
        if target_size_m is None:
            raise InputError(f"PhysX description of {description.name!r} has no Dimension line; cannot give the asset a metric size")
        warnings.append("no Dimension line: the size comes from the target box alone")
        description = replace(description, dimension_cm=(100.0, 100.0, 100.0))
    grids: dict[int, np.ndarray] = {}
    for p in description.parts:
        occ = part_grids.get(p.label)
        if occ is None or not np.asarray(occ).any():
            warnings.append(f"l_{p.label} ({p.name}): no voxels, part dropped")
            continue
        occ = np.asarray(occ, dtype=bool)
        if occ.shape != (g_side,) * 3:
            raise ValueError(f"l_{p.label}: grid shape {occ.shape}, expected ({g_side},)*3")
        if fill_closed_shells:
            filled = ndimage.binary_fill_holes(occ)
            occ = filled
        grids[p.label] = occ
    union = np.zeros((g_side,) * 3, dtype=bool)
    for occ in grids.values():
        union |= occ
    if not union.any():
        raise ProtocolError(f"PhysX object {description.name!r}: no part has any voxel")
    idx = np.argwhere(union)
    lo, hi = idx.min(axis=0), idx.max(axis=0)
    frame, frame_warnings = GridFrame.from_dimension(description.dimension_cm, g_side, (lo, hi), max_anisotropy)
    warnings += frame_warnings
    factors = np.ones(3)
    if target_size_m is not None:
        target = np.asarray(target_size_m, dtype=np.float64)
        if target.shape != (3,) or not np.all(target > 0):
            raise InputError(f"target size must be three positive extents in metres, got {target_size_m}")
        own = (hi - lo + 1.0)[[1, 0, 2]] * frame.metres_per_voxel[[1, 0, 2]]  # asset x, y, z
        factors = target / own
        if factors.max() / factors.min() > max_target_anisotropy:
            raise ProtocolError(
                f"PhysX object {description.name!r}: its proportions {own[0]:.2f} x {own[1]:.2f} x {own[2]:.2f} m and the "
                f"observed box {target[0]:.2f} x {target[1]:.2f} x {target[2]:.2f} m differ by more than {max_target_anisotropy:g}x between axes"
            )
        # asset x = -grid y, asset y = grid x, asset z = grid z
        frame = GridFrame(g_side, frame.metres_per_voxel * factors[[1, 0, 2]], frame.origin_vox)
    sx, sy, sz = frame.metres_per_voxel
    voxel_size = np.array([sy, sx, sz])
    origin = np.array([-(hi[1] + 1 - frame.origin_vox[1]) * sy, (lo[0] - frame.origin_vox[0]) * sx, (lo[2] - frame.origin_vox[2]) * sz])

    names: dict[int, str] = {}
    used: set[str] = set()
    for p in description.parts:
        base = _slug(p.name, f"part_{p.label}")
        name = base if base not in used else f"{base}_{p.label}"
        used.add(name)
        names[p.label] = name

    # group leads: the first member with voxels; groups with none hand their children up
    groups = {g.group_id: g for g in description.groups}
    lead: dict[int, int | None] = {gid: next((m for m in g.members if m in grids), None) for gid, g in groups.items()}
    base_gid = 0
    if lead[0] is None:  # the base has no voxels: the first group that has some becomes the base
        base_gid = next(gid for gid in sorted(groups) if lead[gid] is not None)
        warnings.append(f"group_0 has no voxels: group_{base_gid} becomes the base (its joint dropped)")

    def effective_parent(gid: int) -> int:
        cur = groups[gid].parent
        while cur is not None and lead.get(cur) is None:
            cur = groups[cur].parent
        return base_gid if cur is None else cur

    specs: list[PhysxPartSpec] = []
    parts_by_label = {p.label: p for p in description.parts}
    for gid in sorted(groups):
        g = groups[gid]
        lead_label = lead[gid]
        if lead_label is None:
            if gid != 0:
                warnings.append(f"group_{gid}: no part with voxels, its children attach to its parent")
            continue
        members = [m for m in g.members if m in grids]
        group_occ = np.zeros_like(union)
        for m in members:
            group_occ |= grids[m]
        gidx = np.argwhere(group_occ)
        centre_vox = (gidx.min(axis=0) + gidx.max(axis=0) + 1.0) / 2.0
        for m in members:
            p = parts_by_label[m]
            if gid == base_gid and m == lead_label:
                parent, joint = None, None
            elif m == lead_label:
                parent = names[lead[effective_parent(gid)]]
                joint, jw = group_joint(g, frame, centre_vox)
                warnings += jw
            else:
                parent = names[lead_label]
                joint = Joint(JointType.FIXED, np.array([0.0, 0.0, 1.0]), frame.to_asset(centre_vox)[0])
            crop = grids[m][lo[0] : hi[0] + 1, lo[1] : hi[1] + 1, lo[2] : hi[2] + 1]
            occ_asset = crop.transpose(1, 0, 2)[::-1]
            specs.append(
                PhysxPartSpec(
                    label=m,
                    name=names[m],
                    parent=parent,
                    joint=joint,
                    occupancy=occ_asset,
                    voxel_size_m=voxel_size,
                    origin_m=origin,
                    material=_material(p, warnings),
                    affordance_rank=p.affordance_rank,
                    description=p.description,
                    filled_voxels=int(grids[m].sum() - np.asarray(part_grids[m], dtype=bool).sum()),
                )
            )
    size = (hi - lo + 1.0)[[1, 0, 2]] * voxel_size
    articulated = any(
        s.joint is not None and s.joint.type is not JointType.FIXED for s in specs
    )
    return PhysxObject(
        name=description.name,
        category=description.category,
        kind_articulated=articulated,
        size_m=size,
        parts=tuple(specs),
        frame=frame,
        description=description,
        warnings=tuple(warnings),
        scale_to_target=factors,
    )


def _part_geometry(spec: PhysxPartSpec, config):
    """Isotropic voxels go to the generator as a VoxelGeometry; per-axis voxel sizes are meshed in
    voxel units and scaled per axis here (a scaled watertight mesh stays watertight)."""
    from generation.assembly import VoxelGeometry
    from generation.meshing import mesh_from_occupancy, to_model_mesh

    size = spec.voxel_size_m
    if np.allclose(size, size[0], rtol=1e-9):
        return VoxelGeometry(spec.occupancy, float(size[0]), spec.origin_m)
    tm = mesh_from_occupancy(spec.occupancy, 1.0, np.zeros(3), max_faces=config.max_visual_faces)
    tm.vertices = tm.vertices * size + spec.origin_m
    return to_model_mesh(tm)


def to_object_asset(
    obj: PhysxObject,
    name: str,
    label: str,
    config=None,
    seed: int = 0,
    backend: str = "physx-anything-vlm",
    observed_points_m: np.ndarray | None = None,
    observed_colors_rgb: np.ndarray | None = None,
) -> ObjectAsset:
    """Mesh, weigh and decompose the parts with the generator's ``assemble_asset`` (marching
    cubes, mass and inertia by integration over the watertight mesh, convex collision pieces).
    The PhysX texts give no friction; joints get the generator's derived damping and friction.
    observed_points_m: (N, 3) points seen in the photo, in the asset frame, with their
    observed_colors_rgb (N, 3) uint8: the meshes take the photo's colours, as the shape prior's do."""
    from scene_builder.config import GenerationConfig

    from generation.assembly import JointSpec, PartSpec, assemble_asset

    cfg = config if config is not None else GenerationConfig()
    specs = []
    for p in obj.parts:
        joint = None
        if p.joint is not None:
            j = p.joint
            joint = JointSpec(j.type, j.axis, j.anchor_m, lower=j.lower, upper=j.upper, lower2=j.lower2, upper2=j.upper2)
        specs.append(
            PartSpec(
                name=p.name,
                parent=p.parent,
                geometry=_part_geometry(p, cfg),
                material=p.material,
                joint=joint,
                affordance_rank=p.affordance_rank,
                description=p.description,
            )
        )
    text = f"{obj.name} ({obj.category})" if obj.category else obj.name
    return assemble_asset(
        name, label, specs, config=cfg, seed=seed, description=text, backend=backend, recenter=False,
        observed_points_m=observed_points_m, observed_colors_rgb=observed_colors_rgb,
    )
