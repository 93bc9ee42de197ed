"""USD export with UsdPhysics (usd-core 26.11): ``scene.usda``, Z up, metres, kilograms.

Prim layout::

    /World                          defaultPrim, Xform
      PhysicsScene                  UsdPhysics.Scene, gravity -Z 9.81 m/s^2
      Looks/<mat>                   UsdPreviewSurface material per part material (visual)
      PhysicsMaterials/<mat>        UsdPhysics.MaterialAPI (friction, restitution, density)
      Room/Floor, Room/Wall_i       static colliders (UsdGeom.Plane, purpose guide; a wall seen over a bounded span: a UsdGeom.Cube slab)
      Background/Surface            the observed room as one textured mesh, a static collider
                                    with a triangle-mesh approximation ("none")
      Background/Objects/<obj>      visual meshes of objects that became background
      Background/Collision/...      their convex pieces (convexHull) and the background's
                                    collision boxes (UsdGeom.Cube), static colliders
      InputCamera                   UsdGeom.Camera reproducing the photo's pinhole camera
      Robot                         ``--robot``: an articulation (see exporters/usd_robot.py)
      Objects/<obj>                 Xform at world_from_asset, displayName = original name
        one rigid part:             RigidBodyAPI + MassAPI on <obj>; children Visual, Collision/piece_k
        articulated:                ArticulationRootAPI on <obj>; one Xform per part (identity
                                    transform: parts live in the asset frame) with RigidBodyAPI +
                                    MassAPI; joints under <obj>/Joints

Choices (the validators and Newton accept these):

* Fixed rigid furniture is a static collider: no RigidBodyAPI (UsdPhysics' way of saying
  "does not move"); its mass is kept as the custom attribute ``sceneBuilder:massKg``. Fixed
  articulated furniture keeps rigid bodies and welds its root part to the world with a
  FixedJoint (body0 empty).
* Collision pieces are convex, so ``convexHull`` approximation is exact. They have purpose
  ``guide`` (not rendered) and bind the physics material with purpose ``physics``.
* Photo textures: a ``UsdPreviewSurface`` whose diffuseColor reads a ``UsdUVTexture`` of
  ``./textures/<name>.png`` (relative asset path, so the folder can move) through the mesh's
  ``st`` primvar (vertex interpolation, ``t = 1 - v``). ``--usdz`` packages the stage and its
  textures into one ``scene.usdz``.
* Joint frames: every part frame is the asset frame, so localPos0 = localPos1 = anchor; the
  joint axis token is X and localRot0 = localRot1 rotates X onto ``Joint.axis``. Revolute
  limits are degrees (UsdPhysics), prismatic metres. Joint damping goes to a DriveAPI whose
  stiffness is the joint's counterbalance spring toward target position 0, the rest pose (zero
  but on doors hinged at their bottom; angular gains per degree); dry friction is
  ``mjc:frictionloss`` (MuJoCo's USD schema name, read by Newton), the effort limit the drive's
  maxForce (and ``sceneBuilder:effortLimit``).
* usd-core 26.11 has no UsdPhysics deformable schema: deformables are exported as rigid bodies
  (rigid fallback) carrying ``sceneBuilder:deformable:*`` attributes (Young's modulus, Poisson
  ratio, damping, resolution) so that a soft-body importer can pick them up.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from exporters import names
from exporters.textures import TEXTURE_DIR, scene_textures, texture_file, write_texture
from scene_builder.errors import ExportError
from scene_builder.frames import CV_FROM_GL, quat_wxyz_from_matrix
from scene_builder.model import Background, JointType, ObjectAsset, Part, PlacedObject, Plane, Scene, TriangleMesh

FLOOR_STATIC_FRICTION = 0.6
FLOOR_DYNAMIC_FRICTION = 0.5  # same floor as the MJCF (exporters.mjcf.FLOOR_DYNAMIC_FRICTION)
ROOM_EXTENT_M = 12.0
# USD camera film: horizontal aperture in "tenths of a scene unit" (millimetres by convention).
FILM_WIDTH_MM = 36.0


def write_usd(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.usda``, validate it with every registered ``UsdValidation``
    validator and raise :class:`ExportError` (naming the object) on any error."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "scene.usda"
    for texture in scene_textures(scene):
        write_texture(texture, out_dir)
    stage = build_stage(scene, path)
    stage.GetRootLayer().Save()
    problems = validate_stage(stage)
    if problems:
        raise ExportError(f"USD validation failed for {path.name}: {problems[0]} ({len(problems)} problem(s))")
    return path


def write_usdz(usda_path: Path) -> Path:
    """Package ``scene.usda`` and every asset it references (the textures) as one
    ``scene.usdz`` beside it (``UsdUtils.CreateNewUsdzPackage``), open the package and check the
    stage and its textures are inside."""
    import zipfile

    from pxr import Sdf, Usd, UsdUtils

    usda_path = Path(usda_path).resolve()
    out = usda_path.with_suffix(".usdz")
    if not UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(usda_path)), str(out)):
        raise ExportError(f"USD could not package {usda_path.name} as {out.name}")
    stage = Usd.Stage.Open(str(out))
    if stage is None or not stage.GetDefaultPrim():
        raise ExportError(f"{out.name}: the packaged stage does not open")
    with zipfile.ZipFile(out) as z:
        packed = set(z.namelist())
    missing = sorted(p.relative_to(usda_path.parent).as_posix() for p in (usda_path.parent / TEXTURE_DIR).glob("*.png")
                     if p.relative_to(usda_path.parent).as_posix() not in packed)
    if missing:
        raise ExportError(f"{out.name}: textures missing from the package: {', '.join(missing[:3])}")
    return out


def build_stage(scene: Scene, path: Path | None = None):
    """The ``Usd.Stage`` of ``scene`` (in memory when ``path`` is None)."""
    from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdPhysics

    stage = Usd.Stage.CreateNew(str(path)) if path is not None else Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())

    ps = UsdPhysics.Scene.Define(stage, "/World/PhysicsScene")
    ps.CreateGravityDirectionAttr(Gf.Vec3f(0.0, 0.0, -1.0))
    ps.CreateGravityMagnitudeAttr(9.81)

    ctx = _Context(stage)
    UsdGeom.Scope.Define(stage, "/World/Looks")
    UsdGeom.Scope.Define(stage, "/World/PhysicsMaterials")
    _add_room(ctx, scene)
    if scene.room.background is not None:
        _add_background(ctx, scene.room.background)
    _add_camera(stage, scene)
    UsdGeom.Scope.Define(stage, "/World/Objects")
    prim_names = names.UniqueNames()
    for placed in scene.objects:
        prim_path = Sdf.Path("/World/Objects").AppendChild(prim_names(placed.name))
        try:
            _add_object(ctx, placed, prim_path)
        except Tf.ErrorException as err:  # what pxr raises when it refuses an edit; name the object, keep the cause
            raise ExportError(f"USD export failed at object {placed.name}: {err}") from err
    if scene.robot is not None:
        from exporters.usd_robot import add_robot

        add_robot(stage, scene.robot)
    return stage


class _Context:
    """Stage plus the materials already written (one visual and one physics material per distinct
    Material, deduplicated by value)."""

    def __init__(self, stage) -> None:
        self.stage = stage
        self.looks: dict[tuple, str] = {}
        self.physics: dict[tuple, str] = {}
        self.look_names = names.UniqueNames()
        self.phys_names = names.UniqueNames()

    def look(self, name: str, rgba) -> "object":
        from pxr import Gf, Sdf, UsdShade

        key = (name, tuple(round(float(c), 6) for c in rgba))
        if key not in self.looks:
            path = f"/World/Looks/{self.look_names(name)}"
            mat = UsdShade.Material.Define(self.stage, path)
            shader = UsdShade.Shader.Define(self.stage, f"{path}/PreviewSurface")
            shader.CreateIdAttr("UsdPreviewSurface")
            shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*[float(c) for c in rgba[:3]]))
            shader.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(float(rgba[3]))
            shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.7)
            mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
            self.looks[key] = path
        return UsdShade.Material.Get(self.stage, self.looks[key])

    def photo_look(self, texture) -> "object":
        """A UsdPreviewSurface whose diffuse colour is ``texture`` (file under ./textures/)."""
        from pxr import Sdf, UsdShade

        key = ("photo", texture.name)
        if key not in self.looks:
            path = f"/World/Looks/{self.look_names('photo_' + texture.name)}"
            mat = UsdShade.Material.Define(self.stage, path)
            st_reader = UsdShade.Shader.Define(self.stage, f"{path}/st")
            st_reader.CreateIdAttr("UsdPrimvarReader_float2")
            st_reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
            tex = UsdShade.Shader.Define(self.stage, f"{path}/Texture")
            tex.CreateIdAttr("UsdUVTexture")
            tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(f"./{TEXTURE_DIR}/{texture_file(texture)}"))
            tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st_reader.ConnectableAPI(), "result")
            tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("clamp")
            tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("clamp")
            tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
            tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
            shader = UsdShade.Shader.Define(self.stage, f"{path}/PreviewSurface")
            shader.CreateIdAttr("UsdPreviewSurface")
            shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
            shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.9)
            shader.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(0)
            mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
            self.looks[key] = path
        return UsdShade.Material.Get(self.stage, self.looks[key])

    def physics_material(self, name: str, static: float, dynamic: float, restitution: float, density: float | None):
        from pxr import UsdPhysics, UsdShade

        key = (name, static, dynamic, restitution, density)
        if key not in self.physics:
            path = f"/World/PhysicsMaterials/{self.phys_names(name)}"
            mat = UsdShade.Material.Define(self.stage, path)
            api = UsdPhysics.MaterialAPI.Apply(mat.GetPrim())
            api.CreateStaticFrictionAttr(float(static))
            api.CreateDynamicFrictionAttr(float(dynamic))
            api.CreateRestitutionAttr(float(restitution))
            if density is not None:
                api.CreateDensityAttr(float(density))
            self.physics[key] = path
        return UsdShade.Material.Get(self.stage, self.physics[key])


def _bind(prim, material, purpose: str | None = None) -> None:
    from pxr import UsdShade

    api = UsdShade.MaterialBindingAPI.Apply(prim)
    if purpose is None:
        api.Bind(material)
    else:
        api.Bind(material, UsdShade.Tokens.weakerThanDescendants, purpose)


def _set_transform(xformable, t: np.ndarray) -> None:
    from pxr import Gf

    q = quat_wxyz_from_matrix(t[:3, :3])
    xformable.AddTranslateOp().Set(Gf.Vec3d(*t[:3, 3].tolist()))
    xformable.AddOrientOp().Set(Gf.Quatf(float(q[0]), Gf.Vec3f(*q[1:].tolist())))


def _add_room(ctx: _Context, scene: Scene) -> None:
    from pxr import UsdGeom, UsdPhysics

    stage = ctx.stage
    UsdGeom.Xform.Define(stage, "/World/Room")
    floor_mat = ctx.physics_material("floor", FLOOR_STATIC_FRICTION, FLOOR_DYNAMIC_FRICTION, 0.2, None)
    planes: list[tuple[str, np.ndarray]] = [("Floor", np.eye(4))]
    for i, wall in enumerate(scene.room.walls):
        if wall.bounded:  # (the room goes on past its ends: a slab, as in the MJCF)
            _collision_box(stage, f"/World/Room/Wall_{i}", *wall.slab(), floor_mat)  # (Plane.slab)
        else:
            planes.append((f"Wall_{i}", _plane_transform(wall)))
    for name, t in planes:
        plane = UsdGeom.Plane.Define(stage, f"/World/Room/{name}")
        plane.CreateAxisAttr(UsdGeom.Tokens.z)
        plane.CreateWidthAttr(ROOM_EXTENT_M)
        plane.CreateLengthAttr(ROOM_EXTENT_M)
        plane.CreatePurposeAttr(UsdGeom.Tokens.guide if name != "Floor" else UsdGeom.Tokens.default_)
        _set_transform(plane, t)
        UsdPhysics.CollisionAPI.Apply(plane.GetPrim())
        _bind(plane.GetPrim(), floor_mat, "physics")


def _add_background(ctx: _Context, bg: Background) -> None:
    """The static background (no RigidBodyAPI: colliders that never move): the textured observed
    surface, collided as a triangle mesh (approximation "none", allowed for static colliders), the
    visual meshes and convex pieces of objects that became background, and the collision boxes."""
    from pxr import Sdf, UsdGeom, UsdPhysics

    stage = ctx.stage
    root = Sdf.Path("/World/Background")
    UsdGeom.Xform.Define(stage, root)
    phys = ctx.physics_material("background", FLOOR_STATIC_FRICTION, FLOOR_DYNAMIC_FRICTION, 0.2, None)
    surface = _mesh(stage, root.AppendChild("Surface"), bg.surface, (0.7, 0.7, 0.7, 1.0))
    if bg.surface.texture is not None:
        _bind(surface.GetPrim(), ctx.photo_look(bg.surface.texture))
    if len(bg.surface.faces):
        UsdPhysics.CollisionAPI.Apply(surface.GetPrim())
        UsdPhysics.MeshCollisionAPI.Apply(surface.GetPrim()).CreateApproximationAttr(UsdPhysics.Tokens.none)
        _bind(surface.GetPrim(), phys, "physics")
    objects = root.AppendChild("Objects")
    UsdGeom.Scope.Define(stage, objects)
    unique = names.UniqueNames()
    for label, mesh in zip(bg.static_names, bg.static_meshes):
        m = _mesh(stage, objects.AppendChild(unique(label)), mesh, (0.7, 0.7, 0.7, 1.0))
        m.GetPrim().SetDisplayName(label)
        if mesh.texture is not None:
            _bind(m.GetPrim(), ctx.photo_look(mesh.texture))
    col = root.AppendChild("Collision")
    UsdGeom.Scope.Define(stage, col)
    for k, piece in enumerate(bg.static_pieces):
        c = _mesh(stage, col.AppendChild(f"piece_{k}"), piece)
        c.CreatePurposeAttr(UsdGeom.Tokens.guide)
        UsdPhysics.CollisionAPI.Apply(c.GetPrim())
        UsdPhysics.MeshCollisionAPI.Apply(c.GetPrim()).CreateApproximationAttr(UsdPhysics.Tokens.convexHull)
        _bind(c.GetPrim(), phys, "physics")
    for k in range(bg.box_count):
        _collision_box(stage, col.AppendChild(f"box_{k}"), bg.box_centers_m[k], float(bg.box_yaws_rad[k]), bg.box_half_extents_m[k], phys)


def _collision_box(stage, path, centre_m: np.ndarray, yaw_rad: float, half_m: np.ndarray, material) -> None:
    """A static, guide-purpose box collider (a background box, a bounded wall's slab): a cube of
    size 2 scaled by the half extents, turned by ``yaw_rad`` about Z, at ``centre_m``."""
    from pxr import Gf, UsdGeom, UsdPhysics

    cube = UsdGeom.Cube.Define(stage, path)
    cube.CreateSizeAttr(2.0)
    cube.CreateExtentAttr([Gf.Vec3f(-1.0, -1.0, -1.0), Gf.Vec3f(1.0, 1.0, 1.0)])
    cube.CreatePurposeAttr(UsdGeom.Tokens.guide)
    cube.AddTranslateOp().Set(Gf.Vec3d(*np.asarray(centre_m, dtype=float).tolist()))
    cube.AddOrientOp().Set(Gf.Quatf(float(np.cos(yaw_rad / 2)), Gf.Vec3f(0.0, 0.0, float(np.sin(yaw_rad / 2)))))
    cube.AddScaleOp().Set(Gf.Vec3f(*np.asarray(half_m, dtype=float).tolist()))
    UsdPhysics.CollisionAPI.Apply(cube.GetPrim())
    _bind(cube.GetPrim(), material, "physics")


def _plane_transform(plane: Plane) -> np.ndarray:
    """(4, 4) transform whose Z axis is the plane normal, origin on the plane at floor height."""
    n = plane.normal
    x = np.cross([0.0, 0.0, 1.0], n)
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
    t = np.eye(4)
    t[:3, :3] = np.stack([x, np.cross(n, x), n], axis=1)
    t[:3, 3] = -plane.offset_m * n
    return t


def camera_film(scene: Scene) -> dict[str, float]:
    """UsdGeom.Camera film attributes reproducing the OpenCV intrinsics (same length unit for
    focal length and apertures; a pixel is ``FILM_WIDTH_MM / width`` wide)."""
    k = scene.camera.intrinsics
    px = FILM_WIDTH_MM / k.width_px
    focal = k.fx_px * px
    return {
        "focalLength": focal,
        "horizontalAperture": k.width_px * px,
        # fy may differ from fx: scale the vertical film so that focal / (pixel height) = fy.
        "verticalAperture": k.height_px * focal / k.fy_px,
        # Offset of the film window's centre from the optical axis (a principal point right of
        # the image centre shifts the window left); USD's film y is up, image v is down.
        "horizontalApertureOffset": ((k.width_px - 1) / 2.0 - k.cx_px) * px,
        "verticalApertureOffset": (k.cy_px - (k.height_px - 1) / 2.0) * focal / k.fy_px,
    }


def _add_camera(stage, scene: Scene) -> None:
    from pxr import Gf, UsdGeom

    cam = UsdGeom.Camera.Define(stage, "/World/InputCamera")
    film = camera_film(scene)
    cam.CreateFocalLengthAttr(film["focalLength"])
    cam.CreateHorizontalApertureAttr(film["horizontalAperture"])
    cam.CreateVerticalApertureAttr(film["verticalAperture"])
    cam.CreateHorizontalApertureOffsetAttr(film["horizontalApertureOffset"])
    cam.CreateVerticalApertureOffsetAttr(film["verticalApertureOffset"])
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.01, 100.0))
    t = scene.camera.world_from_camera.copy()
    t[:3, :3] = t[:3, :3] @ CV_FROM_GL  # USD cameras look down -Z with +Y up (OpenGL)
    _set_transform(cam, t)


def _mesh(stage, path, mesh: TriangleMesh, rgba=None):
    from pxr import Gf, Sdf, UsdGeom, Vt

    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(mesh.vertices_m.astype(np.float32)))
    m.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(mesh.faces), 3, dtype=np.int32)))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(mesh.faces.reshape(-1).astype(np.int32)))
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    m.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    lo, hi = mesh.bounds_m
    m.CreateExtentAttr([Gf.Vec3f(*lo.tolist()), Gf.Vec3f(*hi.tolist())])
    if mesh.uv is not None:
        st = np.stack([mesh.uv[:, 0], 1.0 - mesh.uv[:, 1]], axis=1).astype(np.float32)
        UsdGeom.PrimvarsAPI(m).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(Vt.Vec2fArray.FromNumpy(st))
    if rgba is not None:
        if mesh.vertex_colors_rgba is not None:
            c = mesh.vertex_colors_rgba.astype(np.float32) / 255.0
            pv = m.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex)
            pv.Set(Vt.Vec3fArray.FromNumpy(c[:, :3].copy()))
        else:
            m.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set([Gf.Vec3f(*[float(v) for v in rgba[:3]])])
    return m


def _add_part_geometry(ctx: _Context, parent_path, part: Part, asset: ObjectAsset) -> None:
    from pxr import UsdGeom, UsdPhysics

    stage = ctx.stage
    vis = _mesh(stage, parent_path.AppendChild("Visual"), part.visual, part.material.rgba)
    tex = part.visual.texture
    _bind(vis.GetPrim(), ctx.photo_look(tex) if tex is not None else ctx.look(part.material.name, part.material.rgba))
    UsdGeom.Scope.Define(stage, parent_path.AppendChild("Collision"))
    m = part.material
    phys = ctx.physics_material(m.name, m.static_friction, m.dynamic_friction, m.restitution, m.density_kg_m3)
    for k, piece in enumerate(part.collision):
        col = _mesh(stage, parent_path.AppendChild("Collision").AppendChild(f"piece_{k}"), piece)
        col.CreatePurposeAttr(UsdGeom.Tokens.guide)
        UsdPhysics.CollisionAPI.Apply(col.GetPrim())
        UsdPhysics.MeshCollisionAPI.Apply(col.GetPrim()).CreateApproximationAttr(UsdPhysics.Tokens.convexHull)
        _bind(col.GetPrim(), phys, "physics")


def _mass(prim, part: Part) -> None:
    from pxr import Gf, UsdPhysics

    moments, axes = part.inertial.principal()
    q = quat_wxyz_from_matrix(axes)
    api = UsdPhysics.MassAPI.Apply(prim)
    api.CreateMassAttr(float(part.inertial.mass_kg))
    api.CreateCenterOfMassAttr(Gf.Vec3f(*part.inertial.com_m.tolist()))
    api.CreateDiagonalInertiaAttr(Gf.Vec3f(*moments.tolist()))
    api.CreatePrincipalAxesAttr(Gf.Quatf(float(q[0]), Gf.Vec3f(*q[1:].tolist())))


def _custom(prim, name: str, value: float) -> None:
    from pxr import Sdf

    prim.CreateAttribute(f"sceneBuilder:{name}", Sdf.ValueTypeNames.Double, custom=True).Set(float(value))


def _add_object(ctx: _Context, placed: PlacedObject, path) -> None:
    from pxr import UsdGeom, UsdPhysics

    stage = ctx.stage
    asset = placed.asset
    xf = UsdGeom.Xform.Define(stage, path)
    prim = xf.GetPrim()
    prim.SetDisplayName(asset.name)
    prim.CreateAttribute("sceneBuilder:name", _sdf_string()).Set(asset.name)
    prim.CreateAttribute("sceneBuilder:label", _sdf_string()).Set(asset.label)
    _set_transform(xf, placed.world_from_asset)

    if len(asset.parts) == 1:
        part = asset.root
        if asset.is_fixed:
            _custom(prim, "massKg", part.inertial.mass_kg)
        else:
            UsdPhysics.RigidBodyAPI.Apply(prim)
            _mass(prim, part)
        _add_part_geometry(ctx, path, part, asset)
        if asset.deformable is not None:
            d = asset.deformable
            _custom(prim, "deformable:youngsModulusPa", d.youngs_modulus_pa)
            _custom(prim, "deformable:poissonRatio", d.poisson_ratio)
            _custom(prim, "deformable:damping", d.damping)
            _custom(prim, "deformable:thicknessM", d.thickness_m)
            _custom(prim, "deformable:resolution", d.resolution)
        return

    UsdPhysics.ArticulationRootAPI.Apply(prim)
    part_names = names.UniqueNames(reserved=("Joints",))
    part_paths = {p.name: path.AppendChild(part_names(p.name)) for p in asset.parts}
    for part in asset.parts:
        pxf = UsdGeom.Xform.Define(stage, part_paths[part.name])
        pxf.GetPrim().SetDisplayName(part.name)
        UsdPhysics.RigidBodyAPI.Apply(pxf.GetPrim())
        _mass(pxf.GetPrim(), part)
        _add_part_geometry(ctx, part_paths[part.name], part, asset)
    joints = path.AppendChild("Joints")
    UsdGeom.Scope.Define(stage, joints)
    if asset.is_fixed:
        fj = UsdPhysics.FixedJoint.Define(stage, joints.AppendChild("world_weld"))
        fj.CreateBody1Rel().SetTargets([part_paths[asset.root.name]])
        _set_joint_frames(fj, placed.world_from_asset[:3, 3], placed.world_from_asset[:3, :3], np.zeros(3), np.eye(3))
    joint_names = names.UniqueNames(reserved=("world_weld",))
    for part in asset.parts:
        if part.joint is None:
            continue
        _add_joint(stage, joints.AppendChild(joint_names(part.name + "_joint")), asset, part,
                   part_paths[part.parent], part_paths[part.name])


def _sdf_string():
    from pxr import Sdf

    return Sdf.ValueTypeNames.String


def _rotation_x_to(axis: np.ndarray) -> np.ndarray:
    """(3, 3) proper rotation mapping +X onto ``axis`` (unit)."""
    x = np.asarray(axis, dtype=np.float64)
    helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    y = np.cross(helper, x)
    y /= np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)], axis=1)


def _set_joint_frames(joint, pos0, rot0, pos1, rot1) -> None:
    from pxr import Gf

    q0, q1 = quat_wxyz_from_matrix(rot0), quat_wxyz_from_matrix(rot1)
    joint.CreateLocalPos0Attr(Gf.Vec3f(*np.asarray(pos0, float).tolist()))
    joint.CreateLocalRot0Attr(Gf.Quatf(float(q0[0]), Gf.Vec3f(*q0[1:].tolist())))
    joint.CreateLocalPos1Attr(Gf.Vec3f(*np.asarray(pos1, float).tolist()))
    joint.CreateLocalRot1Attr(Gf.Quatf(float(q1[0]), Gf.Vec3f(*q1[1:].tolist())))


def _add_joint(stage, jpath, asset: ObjectAsset, part: Part, body0, body1) -> None:
    from pxr import Sdf, UsdPhysics

    j = part.joint
    assert j is not None
    rot = _rotation_x_to(j.axis)
    if j.type is JointType.REVOLUTE:
        joint = UsdPhysics.RevoluteJoint.Define(stage, jpath)
        joint.CreateAxisAttr(UsdPhysics.Tokens.x)
        joint.CreateLowerLimitAttr(float(np.degrees(j.lower)))
        joint.CreateUpperLimitAttr(float(np.degrees(j.upper)))
        drive_kind = "angular"
    elif j.type is JointType.PRISMATIC:
        joint = UsdPhysics.PrismaticJoint.Define(stage, jpath)
        joint.CreateAxisAttr(UsdPhysics.Tokens.x)
        joint.CreateLowerLimitAttr(float(j.lower))
        joint.CreateUpperLimitAttr(float(j.upper))
        drive_kind = "linear"
    elif j.type is JointType.FIXED:
        joint = UsdPhysics.FixedJoint.Define(stage, jpath)
        drive_kind = None
    elif j.type is JointType.BALL:
        joint = UsdPhysics.SphericalJoint.Define(stage, jpath)
        drive_kind = None
    elif j.type is JointType.REVOLUTE_PRISMATIC:
        # A generic D6 joint: translation and rotation along local X free within limits, the other
        # four degrees of freedom locked with LimitAPI (low > high means locked).
        joint = UsdPhysics.Joint.Define(stage, jpath)
        for dof, (lo, hi) in {
            "transX": (j.lower2, j.upper2), "rotX": (np.degrees(j.lower), np.degrees(j.upper)),
            "transY": (1.0, -1.0), "transZ": (1.0, -1.0), "rotY": (1.0, -1.0), "rotZ": (1.0, -1.0),
        }.items():
            lim = UsdPhysics.LimitAPI.Apply(joint.GetPrim(), dof)
            lim.CreateLowAttr(float(lo))
            lim.CreateHighAttr(float(hi))
        drive_kind = None
    else:
        raise ExportError(f"object {asset.name}: part {part.name} has a {j.type.value} joint, which USD export does not support; make it a separate object")
    joint.CreateBody0Rel().SetTargets([body0])
    joint.CreateBody1Rel().SetTargets([body1])
    _set_joint_frames(joint, j.anchor_m, rot, j.anchor_m, rot)
    prim = joint.GetPrim()
    prim.SetDisplayName(names.joint_name(asset, part))
    if drive_kind is not None and (j.damping > 0 or j.effort_limit > 0):
        drive = UsdPhysics.DriveAPI.Apply(prim, drive_kind)
        drive.CreateTypeAttr("force")
        # the counterbalance spring toward the rest pose (target 0); angular gains per degree
        drive.CreateStiffnessAttr(float(np.radians(j.stiffness)) if drive_kind == "angular" else 0.0)
        drive.CreateTargetPositionAttr(0.0)
        drive.CreateDampingAttr(float(np.radians(j.damping)) if drive_kind == "angular" else float(j.damping))
        drive.CreateTargetVelocityAttr(0.0)
        if j.effort_limit > 0:
            drive.CreateMaxForceAttr(float(j.effort_limit))
    # Dry friction under the MuJoCo USD schema's name, which Newton's importer reads too.
    prim.CreateAttribute("mjc:frictionloss", Sdf.ValueTypeNames.Float, custom=True).Set(float(j.friction))
    _custom(prim, "effortLimit", j.effort_limit)
    _custom(prim, "damping", j.damping)


def validate_stage(stage) -> list[str]:
    """Run every registered ``UsdValidation`` validator (about 30 in usd-core 26.11, including the
    UsdPhysics rigid body, collider, joint and articulation checkers) on ``stage``. Returns the
    error messages (warnings are ignored). The usdz package validators are skipped: they check
    .usdz packaging, which a .usda is not."""
    from pxr import UsdValidation

    reg = UsdValidation.ValidationRegistry()
    metas = [m for m in reg.GetAllValidatorMetadata() if "Package" not in m.name and "Usdz" not in m.name]
    validators = reg.GetOrLoadValidatorsByName([m.name for m in metas])
    ctx = UsdValidation.ValidationContext(validators)
    errors = ctx.Validate(stage)
    out = []
    for e in errors:
        if e.GetType() == UsdValidation.ValidationErrorType.Error:
            sites = ", ".join(str(s.GetPrim().GetPath()) for s in e.GetSites() if s.IsPrim())
            out.append(f"{e.GetValidator().GetMetadata().name if e.GetValidator() else ''}: {e.GetMessage()} [{sites}]")
    return out
