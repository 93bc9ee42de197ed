"""MJCF export with ``mujoco.MjSpec``: floor, walls, camera and every object as bodies, joints,
explicit inertials, a visual mesh and convex collision meshes (names: DEVELOPERS.md).

Layout of a body tree: every part body's frame coincides with its asset frame (parts are
modelled at rest pose in the asset frame), so a child body sits at the identity relative to its
parent and its joint is placed at ``Joint.anchor_m`` along ``Joint.axis``. The root body carries
``world_from_asset``. Geometry is written verbatim in the asset frame (one .obj per mesh under
``meshes/``, relative paths).

Deformables become a MuJoCo flex (volumetric grid of tetrahedra with linear elasticity from
:class:`DeformableSettings`). MuJoCo 4.0 refuses flex elasticity under the implicit integrators
("set integrator='discrete', or 'Euler'"), so a scene with a deformable is written with the
``discrete`` integrator; every other scene uses ``implicitfast``. Both use a 2 ms timestep.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from exporters import names
from exporters.textures import SHARED_FILES, TEXTURE_DIR, texture_file, write_mtl, write_texture
from scene_builder.errors import ExportError
from scene_builder.frames import mujoco_camera, quat_wxyz_from_matrix, transform_points
from scene_builder.model import AssetKind, Background, JointType, ObjectAsset, Part, PlacedObject, Plane, Scene, Texture, TriangleMesh

TIMESTEP_S = 0.002
MESH_DIR = "meshes"
BACKGROUND_GROUP = 0
VISUAL_GROUP = 1
COLLISION_GROUP = 3
WALL_GROUP = 2
# Floor material: a sealed wood / vinyl floor. MuJoCo combines two geoms' friction by the
# maximum, so an object's contact with the floor uses max(object, floor).
FLOOR_DYNAMIC_FRICTION = 0.5
# Contact parameters: time constant 10 ms (>= 2 timesteps, stiff enough for stacking, damping
# ratio 1), impedance 0.95..0.99 over 1 mm. Torsional and rolling friction small but non-zero
# (condim 4 adds torsional friction so boxes do not spin in place).
SOLREF = (0.01, 1.0)
SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)
CONDIM = 4
TORSIONAL_FRICTION = 0.005
ROLLING_FRICTION = 0.0001
WALL_EXTENT_M = 6.0
FLOOR_VISUAL_DROP_M = 0.02
CHECK_STEPS = 100


def write_mjcf(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.xml`` and ``out_dir/meshes/*.obj``; compile the written file, step it
    ``CHECK_STEPS`` times and raise :class:`ExportError` naming the object MuJoCo rejects."""
    out_dir = Path(out_dir)
    (out_dir / MESH_DIR).mkdir(parents=True, exist_ok=True)
    spec = build_spec(scene, out_dir)
    xml = _to_xml(spec, scene, out_dir)
    path = out_dir / "scene.xml"
    path.write_text(xml)
    validate_mjcf(path, scene)
    return path


def build_spec(scene: Scene, out_dir: Path, objects: tuple[PlacedObject, ...] | None = None):
    """The ``mujoco.MjSpec`` of ``scene`` (or of a subset of its objects), writing the mesh files
    under ``out_dir/meshes``."""
    import mujoco

    objects = scene.objects if objects is None else objects
    spec = mujoco.MjSpec()
    spec.modelname = "scene"
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.meshdir = MESH_DIR
    spec.modelfiledir = str(Path(out_dir).resolve())
    spec.option.timestep = TIMESTEP_S
    has_flex = any(o.asset.kind is AssetKind.DEFORMABLE for o in objects)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE if has_flex else mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.gravity = [0.0, 0.0, -9.81]
    spec.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    spec.visual.global_.offwidth = max(640, scene.camera.intrinsics.width_px)
    spec.visual.global_.offheight = max(480, scene.camera.intrinsics.height_px)

    spec.texturedir = TEXTURE_DIR
    bg = scene.room.background
    observed = bg is not None and len(bg.surface.faces) > 0  # the room's own surface is drawn
    _add_lights(spec)
    _add_floor(spec, hidden=observed)
    for i, wall in enumerate(scene.room.walls):
        _add_wall(spec, i, wall, hidden=observed)
    _add_camera(spec, scene)
    looks = _Looks(spec, Path(out_dir))
    if bg is not None:
        _add_background(spec, bg, Path(out_dir), looks)
    for placed in objects:
        if placed.asset.kind is AssetKind.DEFORMABLE:
            _add_flex(spec, placed)
        else:
            _add_object(spec, placed, Path(out_dir), looks)
    if scene.robot is not None and objects is scene.objects:
        from exporters.robot import attach_robot

        attach_robot(spec, scene.robot, Path(out_dir))
    return spec


#: Photo-textured surfaces carry the light of the room they were photographed in: their material
#: emits this share of the texture, and the scene's lights add the rest (PHOTO_EMISSION +
#: headlight ambient + the diffuse light a surface facing the camera gets ~ 1), so rendered from
#: the input camera they look like the photo; untextured things (a robot) are lit as usual.
PHOTO_EMISSION = 0.55
HEADLIGHT_AMBIENT = 0.3
HEADLIGHT_DIFFUSE = 0.15
KEY_DIFFUSE = 0.1


class _Looks:
    """One MuJoCo texture + material per scene texture (written once, by name)."""

    def __init__(self, spec, out_dir: Path) -> None:
        self.spec = spec
        self.out_dir = out_dir
        self.done: set[str] = set()

    def material(self, texture: Texture) -> str:
        import mujoco

        name = f"photo/{texture.name}"
        if name not in self.done:
            write_texture(texture, self.out_dir)
            self.spec.add_texture(name=name, type=mujoco.mjtTexture.mjTEXTURE_2D, file=texture_file(texture))
            mat = self.spec.add_material(name=name, emission=PHOTO_EMISSION, specular=0.0, shininess=0.0, reflectance=0.0)
            mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = name
            self.done.add(name)
        return name


def _yaw_quat(yaw_rad: float) -> list[float]:
    return [float(np.cos(yaw_rad / 2.0)), 0.0, 0.0, float(np.sin(yaw_rad / 2.0))]


def background_meshes(bg: Background, out_dir: Path) -> tuple[list[tuple[str, str, TriangleMesh]], list[str]]:
    """Write the background's mesh files under ``out_dir/meshes`` (shared by MJCF and URDF).
    Returns the visual meshes as (name, file, mesh) -- ``background/surface`` when there is an
    observed surface, ``background/object/NAME`` per object that became background -- and the
    files of the convex pieces (``background/piece/K``), relative to ``meshes/``."""
    mdir = Path(out_dir) / MESH_DIR
    mdir.mkdir(parents=True, exist_ok=True)
    visuals = [("surface", bg.surface)] if len(bg.surface.faces) else []
    visuals += [(f"object/{n}", m) for n, m in zip(bg.static_names, bg.static_meshes)]
    out = []
    for label, mesh in visuals:
        fname = names.file_stem("background", *label.split("/")) + ".obj"
        _write_obj(mdir / fname, mesh)
        out.append((f"background/{label}", fname, mesh))
    pieces = []
    for k, piece in enumerate(bg.static_pieces):
        fname = names.file_stem("background", "piece", str(k)) + ".obj"
        _write_obj(mdir / fname, piece)
        pieces.append(fname)
    return out, pieces


def _add_background(spec, bg: Background, out_dir: Path, looks: _Looks) -> None:
    """The static background in the world body: its textured surface and the visual meshes of
    objects that became background (visual only, group BACKGROUND_GROUP), their convex pieces and
    the collision boxes (group COLLISION_GROUP)."""
    import mujoco

    visuals, pieces = background_meshes(bg, out_dir)
    for gname, fname, mesh in visuals:
        spec.add_mesh(name=gname, file=fname, inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL)
        extra = {"material": looks.material(mesh.texture)} if mesh.texture is not None else {"rgba": _mesh_rgba(mesh)}
        spec.worldbody.add_geom(name=gname, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=gname, contype=0, conaffinity=0,
                                group=BACKGROUND_GROUP, density=0.0, **extra)
    common = dict(group=COLLISION_GROUP, friction=[FLOOR_DYNAMIC_FRICTION, TORSIONAL_FRICTION, ROLLING_FRICTION], condim=CONDIM,
                  solref=list(SOLREF), solimp=list(SOLIMP), rgba=[0.3, 0.5, 0.9, 0.4])
    for k, fname in enumerate(pieces):
        gname = f"background/piece/{k}"
        spec.add_mesh(name=gname, file=fname)
        spec.worldbody.add_geom(name=gname, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=gname, **common)
    for k in range(bg.box_count):
        spec.worldbody.add_geom(name=f"background/box/{k}", type=mujoco.mjtGeom.mjGEOM_BOX, pos=bg.box_centers_m[k],
                                quat=_yaw_quat(float(bg.box_yaws_rad[k])), size=bg.box_half_extents_m[k], **common)


def _mesh_rgba(mesh: TriangleMesh) -> list[float]:
    if mesh.vertex_colors_rgba is not None:
        return (mesh.vertex_colors_rgba.astype(np.float64).mean(axis=0) / 255.0).tolist()
    return [0.7, 0.7, 0.7, 1.0]


# ---------------------------------------------------------------------------------------------


def _add_lights(spec) -> None:
    """Indoor light rig: a soft headlight (ambient fill, as from room walls) and one directional
    ceiling light, without shadows: photo-textured surfaces already carry the room's light and
    shadows (their material emits PHOTO_EMISSION of their texture, and these lights add about
    the rest), while untextured things (a robot) are lit at about 0.7 (visual only: lights do not
    touch the physics)."""
    import mujoco

    spec.visual.headlight.ambient = [HEADLIGHT_AMBIENT] * 3
    spec.visual.headlight.diffuse = [HEADLIGHT_DIFFUSE] * 3
    spec.visual.headlight.specular = [0.02, 0.02, 0.02]
    directional = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    spec.worldbody.add_light(name="key", type=directional, pos=[0.0, 0.0, 3.0], dir=[0.3, 0.2, -1.0],
                             diffuse=[KEY_DIFFUSE] * 3, specular=[0.05, 0.05, 0.05], castshadow=False)


def _add_floor(spec, hidden: bool = False) -> None:
    """The floor: a collision half-space at z = 0. With a background, the observed floor is part
    of the background's surface: the plane goes to the collision group (not drawn), and a drawn
    copy lies FLOOR_VISUAL_DROP_M lower, so it shows only past the observed floor and never
    through it."""
    import mujoco

    spec.add_texture(
        name="floor_grid", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        rgb1=[0.62, 0.58, 0.52], rgb2=[0.57, 0.53, 0.47], width=256, height=256,
    )
    mat = spec.add_material(name="floor", texrepeat=[8.0, 8.0], reflectance=0.0)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "floor_grid"
    spec.worldbody.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[WALL_EXTENT_M, WALL_EXTENT_M, 0.05], material="floor",
        friction=[FLOOR_DYNAMIC_FRICTION, TORSIONAL_FRICTION, ROLLING_FRICTION], condim=CONDIM,
        solref=list(SOLREF), solimp=list(SOLIMP), group=COLLISION_GROUP if hidden else 0,
    )
    if hidden:
        spec.worldbody.add_geom(
            name="floor_visual", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[WALL_EXTENT_M, WALL_EXTENT_M, 0.05], material="floor",
            pos=[0.0, 0.0, -FLOOR_VISUAL_DROP_M], contype=0, conaffinity=0, group=0,
        )


def _plane_pose(plane: Plane) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) on the plane at floor height closest to the origin and a (4,) wxyz quat whose
    z axis is the plane normal and x axis horizontal."""
    n = plane.normal
    p = -plane.offset_m * n
    x = np.cross([0.0, 0.0, 1.0], n)
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(n, x)
    return p, quat_wxyz_from_matrix(np.stack([x, y, n], axis=1))


def _add_wall(spec, i: int, wall: Plane, hidden: bool = False) -> None:
    """A wall is a collision half-space (MuJoCo plane geom), drawn in an off-white paint colour;
    planes are only drawn from their front side, which faces into the room, so they never hide
    the scene from a camera inside it. With a background (which has the observed wall), the
    plane goes to the collision group and is not drawn. A wall seen over a bounded span
    (``Plane.bounded``: the room goes on past its ends) is its slab, a box behind its face, so
    what stands past its ends is not pushed into the room by an infinite plane."""
    import mujoco

    if wall.bounded:
        centre, yaw, half = wall.slab()
        kind, pos, quat, size = mujoco.mjtGeom.mjGEOM_BOX, centre, [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)], half
    else:
        pos, quat = _plane_pose(wall)
        kind, size = mujoco.mjtGeom.mjGEOM_PLANE, [WALL_EXTENT_M, WALL_EXTENT_M, 0.05]
    spec.worldbody.add_geom(
        name=f"wall_{i}", type=kind, pos=pos, quat=quat,
        size=list(size), rgba=[0.86, 0.84, 0.78, 1.0], group=COLLISION_GROUP if hidden else WALL_GROUP,
        friction=[FLOOR_DYNAMIC_FRICTION, TORSIONAL_FRICTION, ROLLING_FRICTION], condim=CONDIM,
        solref=list(SOLREF), solimp=list(SOLIMP),
    )


def _add_camera(spec, scene: Scene) -> None:
    cam = mujoco_camera(scene.camera.world_from_camera, scene.camera.intrinsics)
    c = spec.worldbody.add_camera(name="input_camera", pos=cam["pos"], quat=cam["quat"])
    c.resolution = list(cam["resolution"])
    c.sensor_size = list(cam["sensorsize"])
    c.focal_pixel = list(cam["focalpixel"])
    c.principal_pixel = list(cam["principalpixel"])


def _rows(f, row_format: str, values: np.ndarray) -> None:
    """Write one formatted line per row of ``values`` (N, K): one C-level %-formatting of the
    whole block, about 30x faster than np.savetxt's per-row Python loop on a background mesh."""
    values = np.asarray(values)
    if len(values):
        f.write((row_format * len(values)) % tuple(values.ravel().tolist()))


#: (digest of the mesh, size and mtime of the file) of each OBJ this process wrote: an identical
#: mesh whose file (and material file) is still as written is not formatted and written again.
#: The pipeline's repair rounds export the same scene up to four times with most objects
#: unchanged (a third of a build's export time went to rewriting identical files).
_WRITTEN: dict[str, tuple[bytes, int, int]] = {}
_WRITTEN_MAX = 50_000


def _mesh_digest(mesh: TriangleMesh) -> bytes:
    h = hashlib.blake2b(digest_size=16)
    arrays = [mesh.vertices_m, mesh.faces, mesh.uv]
    if mesh.texture is not None:
        h.update(mesh.texture.name.encode())
        arrays.append(mesh.texture.image_rgb)
    for a in arrays:
        if a is None:
            h.update(b"-")
            continue
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
    return h.digest()


def _file_stamp(path: Path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    return st.st_size, st.st_mtime_ns


def _write_obj(path: Path, mesh: TriangleMesh) -> None:
    """:func:`_write_obj_file` unless this process already wrote the same mesh there and the
    file (and its material file) is unchanged since."""
    key = str(Path(path).resolve())
    digest = _mesh_digest(mesh)
    with SHARED_FILES:
        done = _WRITTEN.get(key)
        if done is not None and done[0] == digest and _file_stamp(Path(path)) == done[1:]:
            if mesh.texture is None or Path(path).with_suffix(".mtl").exists():
                return
        _write_obj_file(path, mesh)
        if len(_WRITTEN) >= _WRITTEN_MAX:
            _WRITTEN.clear()
        stamp = _file_stamp(Path(path))
        if stamp is not None:
            _WRITTEN[key] = (digest, *stamp)


def _write_obj_file(path: Path, mesh: TriangleMesh) -> None:
    """Plain OBJ (positions, texture coordinates when the mesh has them, faces; 1-based), with a
    material library naming the texture for OBJ consumers (MuJoCo takes the texture from the
    MJCF material instead). Written by hand: it is a few lines of numpy, exact (repr-precision
    floats) and keeps vertex order, which exporters that merge or reorder vertices do not
    guarantee. OBJ's ``vt`` runs up from the bottom of the image: ``1 - v`` of the model's
    convention."""
    out_dir = Path(path).parent.parent
    with open(path, "w") as f:
        f.write(f"# {len(mesh.vertices_m)} vertices, {len(mesh.faces)} faces, metres\n")
        if mesh.texture is not None:
            f.write(f"mtllib {write_mtl(Path(path), mesh.texture, out_dir)}\nusemtl photo\n")
        _rows(f, "v %.9g %.9g %.9g\n", mesh.vertices_m)
        if mesh.uv is not None:
            _rows(f, "vt %.9g %.9g\n", np.stack([mesh.uv[:, 0], 1.0 - mesh.uv[:, 1]], axis=1))
            _rows(f, "f %d/%d %d/%d %d/%d\n", np.repeat(mesh.faces + 1, 2, axis=1))
        else:
            _rows(f, "f %d %d %d\n", mesh.faces + 1)


def mesh_files(asset: ObjectAsset, part: Part) -> tuple[str, tuple[str, ...]]:
    """Relative (to ``meshes/``) file names of a part's visual mesh and collision pieces."""
    vis = names.file_stem(asset.name, part.name, "visual") + ".obj"
    col = tuple(names.file_stem(asset.name, part.name, f"collision_{k}") + ".obj" for k in range(len(part.collision)))
    return vis, col


def write_part_meshes(asset: ObjectAsset, out_dir: Path) -> None:
    """Write every part's meshes of ``asset`` under ``out_dir/meshes`` (shared by MJCF and URDF)."""
    mdir = Path(out_dir) / MESH_DIR
    mdir.mkdir(parents=True, exist_ok=True)
    for part in asset.parts:
        vis, cols = mesh_files(asset, part)
        _write_obj(mdir / vis, part.visual)
        for fname, piece in zip(cols, part.collision):
            _write_obj(mdir / fname, piece)


def part_rgba(part: Part) -> list[float]:
    """The part's colour: mean vertex colour when it has vertex colours (MuJoCo has no per-vertex
    colour), else the material's."""
    if part.visual.vertex_colors_rgba is not None:
        return (part.visual.vertex_colors_rgba.astype(np.float64).mean(axis=0) / 255.0).tolist()
    return list(part.material.rgba)


def _children(asset: ObjectAsset) -> dict[str | None, list[Part]]:
    kids: dict[str | None, list[Part]] = {}
    for p in asset.parts:
        kids.setdefault(p.parent, []).append(p)
    return kids


def _add_object(spec, placed: PlacedObject, out_dir: Path, looks: "_Looks") -> None:
    import mujoco

    asset = placed.asset
    write_part_meshes(asset, out_dir)
    t = placed.world_from_asset
    root = spec.worldbody.add_body(name=asset.name, pos=t[:3, 3], quat=quat_wxyz_from_matrix(t[:3, :3]))
    if not asset.is_fixed:
        root.add_freejoint(name=names.free_joint_name(asset))
    kids = _children(asset)

    def fill(body, part: Part) -> None:
        _set_inertial(body, asset, part)
        vis, cols = mesh_files(asset, part)
        bname = names.body_name(asset, part)
        spec.add_mesh(name=f"{bname}/visual", file=vis)
        tex = part.visual.texture
        look = {"material": looks.material(tex)} if tex is not None else {"rgba": part_rgba(part)}
        body.add_geom(
            name=f"{bname}/visual", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"{bname}/visual",
            contype=0, conaffinity=0, group=VISUAL_GROUP, density=0.0, **look,
        )
        mu = part.material.dynamic_friction
        for k, fname in enumerate(cols):
            mname = f"{bname}/collision_{k}"
            spec.add_mesh(name=mname, file=fname)
            body.add_geom(
                name=mname, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mname, group=COLLISION_GROUP,
                friction=[mu, TORSIONAL_FRICTION, ROLLING_FRICTION], condim=CONDIM,
                solref=list(SOLREF), solimp=list(SOLIMP), rgba=[0.9, 0.3, 0.3, 0.4], density=0.0,
            )
        for child in kids.get(part.name, []):
            cbody = body.add_body(name=names.body_name(asset, child))
            _add_joint(cbody, asset, child)
            fill(cbody, child)

    fill(root, asset.root)


def _set_inertial(body, asset: ObjectAsset, part: Part) -> None:
    import mujoco

    moments, axes = part.inertial.principal()
    a, b, c = (float(x) for x in moments)
    # MuJoCo's own test of the moments it is given (no tolerance): said here with the object's
    # name instead of its compiler's "inertia must satisfy A + B >= C". The data model keeps
    # every Inertial inside it with a margin (scene_builder.arrays.inertia_problem).
    if not (a > 0.0 and a + b >= c):
        raise ExportError(f"object {asset.name}: part {part.name} has principal moments {a:.6g}, {b:.6g}, {c:.6g} kg m^2, "
                          "which break A + B >= C (no body has them); its mass properties must come from a closed, unfolded mesh")
    if min(part.inertial.mass_kg, a) <= mujoco.mjMINVAL and (part.parent is not None or not asset.is_fixed):
        raise ExportError(f"object {asset.name}: part {part.name} weighs {part.inertial.mass_kg:.3g} kg with a smallest moment of "
                          f"{a:.3g} kg m^2, under what MuJoCo simulates ({mujoco.mjMINVAL:g}); make it larger or part of the background")
    body.explicitinertial = True
    body.mass = part.inertial.mass_kg
    body.ipos = part.inertial.com_m
    body.iquat = quat_wxyz_from_matrix(axes)
    body.inertia = moments


def _add_joint(body, asset: ObjectAsset, part: Part) -> None:
    import mujoco

    j = part.joint
    assert j is not None
    common = dict(pos=j.anchor_m, axis=j.axis, damping=j.damping, frictionloss=j.friction)
    if j.effort_limit > 0:
        common.update(actfrclimited=mujoco.mjtLimited.mjLIMITED_TRUE, actfrcrange=[-j.effort_limit, j.effort_limit])
    hinge, slide = mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE
    if j.type is JointType.FIXED:
        return
    # the counterbalance spring (toward springref 0, the rest pose) acts on the hinge alone
    spring = dict(stiffness=j.stiffness) if j.stiffness > 0 else {}
    if j.type is JointType.REVOLUTE:
        body.add_joint(name=names.joint_name(asset, part), type=hinge, range=[j.lower, j.upper], **common, **spring)
    elif j.type is JointType.PRISMATIC:
        body.add_joint(name=names.joint_name(asset, part), type=slide, range=[j.lower, j.upper], **common)
    elif j.type is JointType.REVOLUTE_PRISMATIC:
        body.add_joint(name=names.joint_name(asset, part), type=hinge, range=[j.lower, j.upper], **common, **spring)
        body.add_joint(name=names.joint_name(asset, part, "_slide"), type=slide, range=[j.lower2, j.upper2], **common)
    elif j.type is JointType.BALL:
        body.add_joint(name=names.joint_name(asset, part), type=mujoco.mjtJoint.mjJNT_BALL, pos=j.anchor_m,
                       damping=j.damping, frictionloss=j.friction)
    elif j.type is JointType.FREE:
        raise ExportError(f"object {asset.name}: part {part.name} has a free joint; MuJoCo allows free joints only on top-level bodies, split it into its own object")


def flex_grid(placed: PlacedObject) -> tuple[list[int], list[float], np.ndarray]:
    """Node counts (3,), spacing (3,) and the world position of the grid centre of a deformable."""
    asset = placed.asset
    assert asset.deformable is not None
    lo = np.min([p.visual.bounds_m[0] for p in asset.parts], axis=0)
    hi = np.max([p.visual.bounds_m[1] for p in asset.parts], axis=0)
    size = hi - lo
    res = max(2, int(asset.deformable.resolution))
    # Nodes per axis: ``resolution`` along the longest side, proportionally fewer elsewhere (>= 2).
    count = [max(2, int(round(res * s / size.max()))) for s in size]
    radius = flex_radius(placed)
    # Node centres inset by the contact radius so the skin's bounding box matches the asset's.
    spacing = [float(max(s - 2 * radius, 1e-3) / (c - 1)) for s, c in zip(size, count)]
    centre = transform_points(placed.world_from_asset, ((lo + hi) / 2.0)[None])[0]
    return count, spacing, centre


def flex_radius(placed: PlacedObject) -> float:
    size = placed.asset.size_m
    return float(min(0.005, 0.1 * size.min()))


# Conditioning bound of the ``discrete`` integrator's effective metric M + h*D + h^2*K for a flex:
# MuJoCo 4.0 solves it iteratively with a per-vertex 3x3 block preconditioner, which stops
# converging ("Flex stiffness is too ill-conditioned ...", counted as mjWARN_INERTIA every step)
# once (h*damping + h^2) * young * spacing / vertex_mass passes ~70 (measured on the real
# nyuv2_metric3d_00050 pillows and blanket: 63 converges, 88 does not). 30 leaves a margin.
FLEX_METRIC_RATIO_MAX = 30.0


def flex_elasticity(placed: PlacedObject) -> tuple[float, float]:
    """Young's modulus (Pa) and Rayleigh damping (s) written for a deformable's flex.

    The grid is a coarse volumetric proxy (a few dozen nodes), so a vertex carries
    ``mass / nodes`` and spans the mean grid spacing ``L``. The settings are kept when
    ``(h*damping + h^2) * young * L / m_vertex <= FLEX_METRIC_RATIO_MAX``; otherwise damping is
    lowered first (not below one timestep, the low end of MuJoCo's recommended 2--50 ms), then
    the modulus is capped: a stiffer grid than that cannot be resolved at this timestep anyway
    (e.g. a folded blanket given fabric's in-plane 5 MPa is capped to ~0.3 MPa)."""
    s = placed.asset.deformable
    assert s is not None
    count, spacing, _ = flex_grid(placed)
    m_vertex = placed.asset.mass_kg / float(np.prod(count))
    length_m = float(np.mean(spacing))
    h = TIMESTEP_S
    budget = FLEX_METRIC_RATIO_MAX * m_vertex / length_m  # bound on (h*damping + h^2) * young
    young = float(s.youngs_modulus_pa)
    damping = float(min(s.damping, max(h, budget / (young * h) - h)))
    young = float(min(young, budget / (h * damping + h * h)))
    return young, damping


def _add_flex(spec, placed: PlacedObject) -> None:
    import mujoco

    asset = placed.asset
    s = asset.deformable
    assert s is not None
    count, spacing, centre = flex_grid(placed)
    mat = asset.root.material
    f = spec.worldbody.make_flex(
        asset.name, type="grid", dim=3, count=count, spacing=spacing, radius=flex_radius(placed),
        mass=asset.mass_kg, pos=centre, quat=quat_wxyz_from_matrix(placed.world_from_asset[:3, :3]),
    )
    young_pa, damping_s = flex_elasticity(placed)
    f.young = young_pa
    f.poisson = s.poisson_ratio
    f.damping = damping_s
    f.friction = [mat.dynamic_friction, TORSIONAL_FRICTION, ROLLING_FRICTION]
    f.condim = 3
    f.solref = list(SOLREF)
    f.solimp = list(SOLIMP)
    f.selfcollide = mujoco.mjtFlexSelf.mjFLEXSELF_NONE
    f.rgba = list(mat.rgba)


XML_DIGITS = 12


def _xml_precision(digits: int | None) -> int | None:
    """Set MuJoCo's XML writer precision (significant digits), returning the previous value.

    MuJoCo writes 6 significant digits by default, which moves joint limits by up to 4e-6 rad and
    inertias by 2e-6 relative. The setter is exported by libmujoco but not by the Python
    bindings, so it is reached with ctypes; when a MuJoCo build lacks it, the default stays."""
    import ctypes
    import glob
    import os

    import mujoco

    libs = sorted(glob.glob(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco.so*")))
    if not libs:
        return None
    lib = ctypes.CDLL(libs[0])
    if not hasattr(lib, "_mjPRIVATE__set_xml_precision") or not hasattr(lib, "_mjPRIVATE__get_xml_precision"):
        return None
    previous = int(lib._mjPRIVATE__get_xml_precision())
    if digits is not None:
        lib._mjPRIVATE__set_xml_precision(int(digits))
    return previous


def _to_xml(spec, scene: Scene, out_dir: Path) -> str:
    try:
        spec.compile()
    except ValueError as err:
        raise ExportError(_culprit(scene, out_dir, err)) from err
    previous = _xml_precision(XML_DIGITS)
    try:
        return spec.to_xml()
    finally:
        if previous is not None:
            _xml_precision(previous)


def _culprit(scene: Scene, out_dir: Path, err: Exception) -> str:
    """Compile the objects one at a time to name the one MuJoCo rejects."""
    for placed in scene.objects:
        try:
            build_spec(scene, out_dir, (placed,)).compile()
        except ValueError as one:
            first = str(one).strip().splitlines()[0]
            return f"MuJoCo rejects object {placed.name}: {first}; check its meshes (watertight, non-degenerate) and inertial"
    first = str(err).strip().splitlines()[0]
    return f"MuJoCo rejects the scene (no single object fails alone): {first}"


def validate_mjcf(path: Path, scene: Scene, steps: int = CHECK_STEPS) -> None:
    """Load the written file as a consumer would, step it and check every value stays finite."""
    import mujoco

    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except ValueError as err:
        raise ExportError(f"MuJoCo cannot load {path.name}: {str(err).strip().splitlines()[0]}") from err
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for _ in range(steps):
        mujoco.mj_step(model, data)
    bad = []
    for placed in scene.objects:
        if placed.asset.kind is AssetKind.DEFORMABLE:
            continue
        bid = model.body(placed.name).id
        if not (np.all(np.isfinite(data.xpos[bid])) and np.all(np.isfinite(data.cvel[bid]))):
            bad.append(placed.name)
    if bad or not np.all(np.isfinite(data.qpos)) or not np.all(np.isfinite(data.qvel)):
        who = ", ".join(bad) if bad else "a deformable"
        raise ExportError(f"MuJoCo simulation of {path.name} diverges (NaN) at object {who}; check its inertial and collision pieces")
