"""SDF export: ``scene.sdf``, one SDFormat 1.9 ``<world>`` (Gazebo, gz-sim, Drake and other
SDFormat consumers).

* The world: gravity ``0 0 -9.81``, a 2 ms physics step (as the MJCF), an ambient light and one
  directional ``key`` light without shadows.
* ``room``: a static model. Its link ``room`` holds the floor (a collision plane at z = 0) and the
  walls (collision planes, normals into the room; a wall of bounded span: a box slab), drawn when there is no observed background;
  its link ``background`` holds the static background: the photo-textured surface and the
  objects that became background as visuals, their convex pieces and the collision boxes.
* ``input_camera``: a static model whose link carries the camera sensor ``input_camera``: the
  photo's camera, with its image size, ``horizontal_fov`` and lens intrinsics (fx, fy, cx, cy).
  SDFormat cameras look along +X with +Z up (the OpenCV camera frame turned by ``GZ_FROM_CV``);
  Gazebo puts the principal point of a centred camera at (W/2, H/2), pixel corners on integer
  coordinates, where OpenCV's is ((W - 1)/2, (H - 1)/2): cx and cy are written plus half a pixel.
* Each object is a model at ``world_from_asset`` named after it (sanitised, unique). Every part
  is a link at the model origin (parts are modelled at rest in the asset frame, as in the MJCF),
  with its inertial (mass, centre of mass, full inertia tensor), its visual mesh (the object's
  colour, its photo texture as ``albedo_map``) and one collision per convex piece with the
  material's surface: Coulomb friction (ODE ``mu``, Bullet ``friction``; the dynamic coefficient
  as in the MJCF), torsional friction over the MJCF's patch radius, rolling friction,
  restitution, Young's modulus and Poisson's ratio. Joints: ``revolute`` / ``prismatic`` with
  limits, damping and dry friction (a revolute joint's counterbalance spring as
  ``spring_stiffness`` toward ``spring_reference`` 0, the rest pose); ``fixed``; ``ball``; a
  revolute-prismatic joint becomes a prismatic and a revolute joint through a 1 g link (as in
  the URDF). A free object's root link
  has no joint (a free body). Fixed furniture is ``static`` when it is one part; with moving parts
  (a built-in cabinet whose doors open) its root link is welded to ``world`` by a fixed joint
  instead, since a static model's joints cannot move. SDFormat has no soft bodies: a deformable
  is written as its rigid shape (mass and meshes), as in the URDF.
* Meshes: the same .obj files as the MJCF and URDF (``meshes/``, relative URIs).
* ``robot`` (with ``--robot``): its links, joints and position controllers
  (:mod:`exporters.sdf_robot`).

Validated after writing: a structural check in Python (XML, version, every object's model and
links, inertials, joint parents and children, every mesh and texture inside the folder), and,
when an SDFormat checker is found (:func:`find_checker`: the ``sdf_check`` program built from
``scripts/sdf_check.cc`` against libsdformat, or ``gz sdf -k``), a load by the SDFormat library
whose masses and joints must agree with the scene.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from exporters import names
from exporters.mjcf import (
    FLOOR_DYNAMIC_FRICTION,
    FLOOR_VISUAL_DROP_M,
    KEY_DIFFUSE,
    MESH_DIR,
    ROLLING_FRICTION,
    TIMESTEP_S,
    TORSIONAL_FRICTION,
    WALL_EXTENT_M,
    background_meshes,
    mesh_files,
    part_rgba,
    write_part_meshes,
)
from exporters.sdf_xml import fmt as _fmt, sub as _sub
from exporters.textures import TEXTURE_DIR, texture_file, write_texture
from exporters.urdf import rpy_from_matrix
from scene_builder.errors import ExportError
from scene_builder.model import JointType, Material, ObjectAsset, Part, PlacedObject, Plane, Scene, TriangleMesh

SDF_VERSION = "1.9"
#: Where :func:`find_checker` looks first for the libsdformat checker (a path to the program).
CHECKER_ENV = "SCENE_BUILDER_SDF_CHECK"
#: The checker's program name (in the virtual environment's bin folder or on PATH).
CHECKER_NAME = "scene-builder-sdf-check"
CHECKER_TIMEOUT_S = 120.0
#: Rotation taking SDFormat camera axes (x forward, y left, z up) to OpenCV's (x right, y down,
#: z forward): columns are the SDFormat axes written in the OpenCV frame.
CV_FROM_GZ = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
CAMERA_CLIP_M = (0.02, 50.0)
CAMERA_RATE_HZ = 30.0
SLIDE_LINK_MASS_KG = 0.001
# Reserved at the world level: the models and light this module writes besides the objects.
_WORLD_NAMES = ("world", "room", "input_camera", "key", "robot")
# Grey of untextured background meshes (as the URDF's).
_GREY = (0.7, 0.7, 0.7, 1.0)
_WALL_RGBA = (0.86, 0.84, 0.78, 1.0)
_FLOOR_RGBA = (0.6, 0.56, 0.5, 1.0)


def _pose(parent: ET.Element, xyz, rpy=(0.0, 0.0, 0.0)) -> None:
    _sub(parent, "pose", _fmt(np.concatenate([np.asarray(xyz, float), np.asarray(rpy, float)])))


class _Ids:
    """SDFormat names: unique among siblings, never ``__``-delimited (reserved) and never holding
    ``::`` (the scope separator). ``names.UniqueNames`` sanitises to ``[A-Za-z0-9_]``."""

    def __init__(self, reserved: tuple[str, ...] = ()) -> None:
        self._unique = names.UniqueNames(reserved)

    def __call__(self, name: str) -> str:
        return self._unique(names.valid_identifier(name).strip("_") or "unnamed")


def write_sdf(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.sdf`` (meshes under ``out_dir/meshes``), validate it (see the module
    docstring) and raise :class:`ExportError` naming what is wrong."""
    out_dir = Path(out_dir)
    sdf = ET.Element("sdf", version=SDF_VERSION)
    world = _sub(sdf, "world", name="scene")
    _world_settings(world)
    _add_room(world, scene, out_dir)
    _add_camera(world, scene)
    model_names = object_model_names(scene)
    for placed in scene.objects:
        write_part_meshes(placed.asset, out_dir)
        _add_object(world, placed, model_names[placed.name])
    if scene.robot is not None:
        from exporters.sdf_robot import add_robot

        add_robot(world, scene.robot, out_dir)
    ET.indent(sdf)
    path = out_dir / "scene.sdf"
    path.write_text('<?xml version="1.0"?>\n' + ET.tostring(sdf, encoding="unicode") + "\n")
    validate_sdf(path, scene)
    return path


def object_model_names(scene: Scene) -> dict[str, str]:
    """The SDF model name of every object (object name -> model name), as :func:`write_sdf` gives them."""
    ids = _Ids(_WORLD_NAMES)
    return {placed.name: ids(placed.name) for placed in scene.objects}


def part_link_names(asset: ObjectAsset) -> dict[str, str]:
    """The SDF link name of every part of ``asset`` (part name -> link name) in its model."""
    ids = _Ids()
    return {p.name: ids(p.name) for p in asset.parts}


def _world_settings(world: ET.Element) -> None:
    _sub(world, "gravity", (0.0, 0.0, -9.81))
    physics = _sub(world, "physics", name="default", type="ode")
    _sub(physics, "max_step_size", f"{TIMESTEP_S:g}")
    _sub(physics, "real_time_factor", "1")
    scene = _sub(world, "scene")
    _sub(scene, "ambient", (0.4, 0.4, 0.4, 1.0))
    _sub(scene, "background", (0.8, 0.8, 0.8, 1.0))
    _sub(scene, "shadows", "false")
    light = _sub(world, "light", name="key", type="directional")
    _pose(light, (0.0, 0.0, 3.0))
    _sub(light, "cast_shadows", "false")
    _sub(light, "diffuse", (KEY_DIFFUSE * 5,) * 3 + (1.0,))
    _sub(light, "specular", (0.05, 0.05, 0.05, 1.0))
    _sub(light, "direction", (0.3, 0.2, -1.0))


def _surface(parent: ET.Element, mu: float, material: Material | None = None) -> None:
    """Contact surface: the MJCF's friction (dynamic coefficient; torsional friction as a
    coefficient of 1 over a patch of radius TORSIONAL_FRICTION, which bounds the torque at
    TORSIONAL_FRICTION x normal force as MuJoCo's torsional friction does), and the material's
    restitution and elasticity when given."""
    surface = _sub(parent, "surface")
    friction = _sub(surface, "friction")
    ode = _sub(friction, "ode")
    _sub(ode, "mu", f"{mu:.9g}")
    _sub(ode, "mu2", f"{mu:.9g}")
    torsional = _sub(friction, "torsional")
    _sub(torsional, "coefficient", "1")
    _sub(torsional, "use_patch_radius", "true")
    _sub(torsional, "patch_radius", f"{TORSIONAL_FRICTION:g}")
    bullet = _sub(friction, "bullet")
    _sub(bullet, "friction", f"{mu:.9g}")
    _sub(bullet, "friction2", f"{mu:.9g}")
    _sub(bullet, "rolling_friction", f"{ROLLING_FRICTION:g}")
    if material is not None:
        bounce = _sub(surface, "bounce")
        _sub(bounce, "restitution_coefficient", f"{material.restitution:.9g}")
        contact = _sub(surface, "contact")
        _sub(contact, "poissons_ratio", f"{material.poisson_ratio:.9g}")
        _sub(contact, "elastic_modulus", f"{material.youngs_modulus_pa:.9g}")


def _mesh(parent: ET.Element, fname: str) -> None:
    _sub(_sub(_sub(parent, "geometry"), "mesh"), "uri", f"{MESH_DIR}/{fname}")


def _material(visual: ET.Element, rgba, texture_rel: str | None = None) -> None:
    mat = _sub(visual, "material")
    _sub(mat, "ambient", rgba)
    _sub(mat, "diffuse", rgba)
    _sub(mat, "specular", (0.05, 0.05, 0.05, 1.0))
    if texture_rel is not None:
        metal = _sub(_sub(mat, "pbr"), "metal")
        _sub(metal, "albedo_map", texture_rel)
        _sub(metal, "metalness", "0")
        _sub(metal, "roughness", "1")


def _plane(parent: ET.Element, kind: str, name: str, normal, point, rgba=None, mu: float = FLOOR_DYNAMIC_FRICTION) -> None:
    el = _sub(parent, kind, name=name)
    _pose(el, point)
    plane = _sub(_sub(el, "geometry"), "plane")
    _sub(plane, "normal", normal)
    _sub(plane, "size", (2 * WALL_EXTENT_M, 2 * WALL_EXTENT_M))
    if kind == "collision":
        _surface(el, mu)
    else:
        _material(el, rgba)


def _box(parent: ET.Element, kind: str, name: str, centre_m, yaw_rad: float, half_m, rgba=None) -> None:
    """A box turned by ``yaw_rad`` about Z at ``centre_m``: a collision (floor friction) or a
    visual (``rgba``). Background boxes and bounded walls' slabs."""
    el = _sub(parent, kind, name=name)
    _pose(el, centre_m, (0.0, 0.0, yaw_rad))
    _sub(_sub(_sub(el, "geometry"), "box"), "size", 2.0 * np.asarray(half_m, dtype=float))
    if kind == "collision":
        _surface(el, FLOOR_DYNAMIC_FRICTION)
    else:
        _material(el, rgba)


def _slab(parent: ET.Element, name: str, wall: Plane, rgba) -> None:
    """A bounded wall's box (``Plane.slab``): collision, and visual when ``rgba`` is given."""
    for kind in ("collision", "visual") if rgba is not None else ("collision",):
        _box(parent, kind, name, *wall.slab(), rgba)


def _add_room(world: ET.Element, scene: Scene, out_dir: Path) -> None:
    """The static ``room`` model: floor and walls, and the background (module docstring)."""
    model = _sub(world, "model", name="room")
    _sub(model, "static", "true")
    room = _sub(model, "link", name="room")
    bg = scene.room.background
    observed = bg is not None and len(bg.surface.faces) > 0
    _plane(room, "collision", "floor", (0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    # With an observed surface the drawn floor lies lower, so it shows only past the observed one.
    _plane(room, "visual", "floor", (0.0, 0.0, 1.0), (0.0, 0.0, -FLOOR_VISUAL_DROP_M if observed else 0.0), _FLOOR_RGBA)
    for i, wall in enumerate(scene.room.walls):
        if wall.bounded:  # (the room goes on past its ends: a slab, as in the MJCF)
            _slab(room, f"wall_{i}", wall, None if observed else _WALL_RGBA)
            continue
        point = -wall.offset_m * wall.normal
        _plane(room, "collision", f"wall_{i}", wall.normal, point)
        if not observed:
            _plane(room, "visual", f"wall_{i}", wall.normal, point, _WALL_RGBA)
    if bg is None:
        return
    link = _sub(model, "link", name="background")
    ids = _Ids()
    visuals, pieces = background_meshes(bg, out_dir)
    for label, fname, mesh in visuals:
        visual = _sub(link, "visual", name=ids(label))
        _mesh(visual, fname)
        _material(visual, _mesh_rgba(mesh), _texture(mesh, out_dir))
    for k, fname in enumerate(pieces):
        col = _sub(link, "collision", name=f"piece_{k}")
        _mesh(col, fname)
        _surface(col, FLOOR_DYNAMIC_FRICTION)
    for k in range(bg.box_count):
        _box(link, "collision", f"box_{k}", bg.box_centers_m[k], float(bg.box_yaws_rad[k]), bg.box_half_extents_m[k])


def _mesh_rgba(mesh: TriangleMesh) -> tuple[float, ...]:
    if mesh.vertex_colors_rgba is not None:
        return tuple(mesh.vertex_colors_rgba.astype(np.float64).mean(axis=0) / 255.0)
    return _GREY


def _texture(mesh: TriangleMesh, out_dir: Path) -> str | None:
    return None if mesh.texture is None else write_texture(mesh.texture, out_dir)


def camera_pose(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) and roll-pitch-yaw (3,) of the SDFormat camera frame in the world."""
    t = scene.camera.world_from_camera
    return t[:3, 3].copy(), rpy_from_matrix(t[:3, :3] @ CV_FROM_GZ)


def _add_camera(world: ET.Element, scene: Scene) -> None:
    k = scene.camera.intrinsics
    model = _sub(world, "model", name="input_camera")
    _sub(model, "static", "true")
    _pose(model, *camera_pose(scene))
    sensor = _sub(_sub(model, "link", name="link"), "sensor", name="input_camera", type="camera")
    _sub(sensor, "always_on", "true")
    _sub(sensor, "update_rate", f"{CAMERA_RATE_HZ:g}")
    camera = _sub(sensor, "camera", name="input_camera")
    _sub(camera, "horizontal_fov", f"{2.0 * np.arctan2(k.width_px / 2.0, k.fx_px):.9g}")
    image = _sub(camera, "image")
    _sub(image, "width", str(k.width_px))
    _sub(image, "height", str(k.height_px))
    _sub(image, "format", "R8G8B8")
    clip = _sub(camera, "clip")
    _sub(clip, "near", f"{CAMERA_CLIP_M[0]:g}")
    _sub(clip, "far", f"{CAMERA_CLIP_M[1]:g}")
    intrinsics = _sub(_sub(camera, "lens"), "intrinsics")
    for tag, value in (("fx", k.fx_px), ("fy", k.fy_px), ("cx", k.cx_px + 0.5), ("cy", k.cy_px + 0.5), ("s", 0.0)):
        _sub(intrinsics, tag, f"{value:.9g}")


def _add_object(world: ET.Element, placed: PlacedObject, model_name: str) -> None:
    asset = placed.asset
    model = _sub(world, "model", name=model_name)
    moving_parts = any(p.joint is not None and p.joint.type is not JointType.FIXED for p in asset.parts)
    if asset.is_fixed and not moving_parts:
        _sub(model, "static", "true")
    t = placed.world_from_asset
    _pose(model, t[:3, 3], rpy_from_matrix(t[:3, :3]))
    links = part_link_names(asset)
    ids = _Ids(tuple(links.values()))  # joint and extra link names, never a part's link name
    for part in asset.parts:  # the root part first: ObjectAsset keeps it where the generator put it
        _link(model, links[part.name], asset, part)
    if asset.is_fixed and moving_parts:
        j = _sub(model, "joint", name=ids("world_fixed"), type="fixed")
        _sub(j, "parent", "world")
        _sub(j, "child", links[asset.root.name])
    for part in asset.parts:
        if part.joint is not None:
            _add_joint(model, ids, links, asset, part)


def _inertial(link: ET.Element, mass_kg: float, com_m, inertia: np.ndarray) -> None:
    el = _sub(link, "inertial")
    _pose(el, com_m)
    _sub(el, "mass", f"{mass_kg:.9g}")
    tensor = _sub(el, "inertia")
    for tag, (r, c) in (("ixx", (0, 0)), ("ixy", (0, 1)), ("ixz", (0, 2)), ("iyy", (1, 1)), ("iyz", (1, 2)), ("izz", (2, 2))):
        _sub(tensor, tag, f"{inertia[r, c]:.9g}")


def _link(model: ET.Element, name: str, asset: ObjectAsset, part: Part) -> None:
    link = _sub(model, "link", name=name)
    _inertial(link, part.inertial.mass_kg, part.inertial.com_m, part.inertial.inertia_kg_m2)
    vis_file, col_files = mesh_files(asset, part)
    visual = _sub(link, "visual", name="visual")
    _mesh(visual, vis_file)
    tex = part.visual.texture
    _material(visual, part_rgba(part), None if tex is None else f"{TEXTURE_DIR}/{texture_file(tex)}")
    for k, fname in enumerate(col_files):
        col = _sub(link, "collision", name=f"collision_{k}")
        _mesh(col, fname)
        _surface(col, part.material.dynamic_friction, part.material)


def _add_joint(model: ET.Element, ids: _Ids, links: dict[str, str], asset: ObjectAsset, part: Part) -> None:
    jt = part.joint
    assert jt is not None and part.parent is not None

    def joint(name: str, kind: str, parent: str, child: str, lo: float = 0.0, hi: float = 0.0) -> None:
        j = _sub(model, "joint", name=name, type=kind)
        _pose(j, jt.anchor_m)  # in the child link's frame, which is the asset frame
        _sub(j, "parent", parent)
        _sub(j, "child", child)
        if kind in ("revolute", "prismatic"):
            axis = _sub(j, "axis")
            _sub(axis, "xyz", jt.axis)
            limit = _sub(axis, "limit")
            _sub(limit, "lower", f"{lo:.9g}")
            _sub(limit, "upper", f"{hi:.9g}")
            _sub(limit, "effort", f"{jt.effort_limit:.9g}" if jt.effort_limit > 0 else "-1")
            dynamics = _sub(axis, "dynamics")
            _sub(dynamics, "damping", f"{jt.damping:.9g}")
            _sub(dynamics, "friction", f"{jt.friction:.9g}")
            if kind == "revolute" and jt.stiffness > 0:  # the counterbalance spring toward the rest pose
                _sub(dynamics, "spring_reference", "0")
                _sub(dynamics, "spring_stiffness", f"{jt.stiffness:.9g}")

    parent, child = links[part.parent], links[part.name]
    kinds = {JointType.REVOLUTE: "revolute", JointType.PRISMATIC: "prismatic", JointType.FIXED: "fixed", JointType.BALL: "ball"}
    if jt.type in kinds:
        joint(ids(f"{part.name}_joint"), kinds[jt.type], parent, child, jt.lower, jt.upper)
    elif jt.type is JointType.REVOLUTE_PRISMATIC:
        mid = ids(f"{part.name}_slide")
        link = _sub(model, "link", name=mid)
        # A moving link needs a mass: 1 g with a tiny inertia at the joint (as in the URDF).
        _inertial(link, SLIDE_LINK_MASS_KG, jt.anchor_m, np.eye(3) * 1e-9)
        joint(ids(f"{part.name}_slide_joint"), "prismatic", parent, mid, jt.lower2, jt.upper2)
        joint(ids(f"{part.name}_joint"), "revolute", mid, child, jt.lower, jt.upper)
    # JointType.FREE: no joint; the part is a free link of its model.


# ---------------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------------


def find_checker() -> list[str] | None:
    """The command that loads an SDF file with libsdformat, without the file argument: the
    program named by ``$SCENE_BUILDER_SDF_CHECK``, else ``scene-builder-sdf-check`` beside the
    Python interpreter (``scripts/bootstrap.sh`` builds it into the virtual environment) or on
    PATH, else Gazebo's ``gz sdf -k``; None when there is none."""
    env = os.environ.get(CHECKER_ENV)
    if env:
        return [env]
    beside = Path(sys.executable).parent / CHECKER_NAME
    if beside.is_file() and os.access(beside, os.X_OK):
        return [str(beside)]
    found = shutil.which(CHECKER_NAME)
    if found:
        return [found]
    gz = shutil.which("gz")
    return [gz, "sdf", "-k"] if gz else None


def run_checker(path: Path, command: list[str] | None = None) -> dict | None:
    """Load ``path`` with the SDFormat checker (:func:`find_checker` unless ``command`` is given)
    and raise :class:`ExportError` with its first error. Returns what ``sdf_check`` reports (a
    dict, see scripts/sdf_check.cc), None for ``gz sdf -k`` (which reports nothing) or when there
    is no checker."""
    command = find_checker() if command is None else command
    if command is None:
        return None
    try:
        proc = subprocess.run([*command, str(path)], capture_output=True, text=True, timeout=CHECKER_TIMEOUT_S, check=False)
    except (OSError, subprocess.TimeoutExpired) as err:
        raise ExportError(f"the SDFormat checker {command[0]} did not run on {path.name}: {err}; set {CHECKER_ENV} to a working one") from err
    errors = [line for line in (proc.stderr + proc.stdout).splitlines() if "rror" in line]
    if proc.returncode != 0 or (command[-1] == "-k" and errors):
        first = (errors or proc.stderr.strip().splitlines() or [f"exit status {proc.returncode}"])[0]
        raise ExportError(f"libsdformat rejects {path.name}: {first.strip()}")
    if command[-1] == "-k":
        return None
    try:
        return json.loads(proc.stdout)
    except ValueError as err:
        raise ExportError(f"the SDFormat checker {command[0]} printed no report for {path.name}: {err}") from err


def validate_sdf(path: Path, scene: Scene, command: list[str] | None = None) -> dict | None:
    """Check ``path`` structurally (always) and with libsdformat (when a checker is found): every
    object a model with its links, positive masses, joints between links of their model, every
    referenced file inside the folder, the input camera; with the checker, the same total mass
    and number of joints as the scene. Returns the checker's report (or None)."""
    problems = structural_problems(path)
    if problems:
        raise ExportError(f"{path.name}: {problems[0]}")
    models = {m.get("name"): m for m in ET.parse(path).getroot().iter("model")}
    for placed, model_name in zip(scene.objects, object_model_names(scene).values()):
        model = models.get(model_name)
        if model is None or len(model.findall("link")) < len(placed.asset.parts):
            raise ExportError(f"{path.name}: object {placed.name} has no model {model_name} with a link per part")
    report = run_checker(path, command)
    if report is not None:
        # Plus the 1 g link of every revolute-prismatic joint.
        want_mass = sum(o.asset.mass_kg for o in scene.objects) + SLIDE_LINK_MASS_KG * sum(
            p.joint is not None and p.joint.type is JointType.REVOLUTE_PRISMATIC for o in scene.objects for p in o.asset.parts
        )
        got = [m for m in report["models"] if m["name"] in set(object_model_names(scene).values())]
        got_mass = sum(link["mass"] for m in got for link in m["links"])
        if not np.isclose(got_mass, want_mass, rtol=1e-6):
            raise ExportError(f"{path.name}: libsdformat reads {got_mass:.6g} kg of objects, the scene has {want_mass:.6g} kg")
        invalid = [f"{m['name']}::{link['name']}" for m in got for link in m["links"] if not link["inertia_valid"]]
        if invalid:
            raise ExportError(f"{path.name}: libsdformat finds physically invalid mass properties in link {invalid[0]}")
        if not any(c for m in report["models"] for link in m["links"] for c in link["cameras"]):
            raise ExportError(f"{path.name}: libsdformat finds no camera sensor")
        if scene.robot is not None:
            _check_robot(path, scene, report)
    return report


def _check_robot(path: Path, scene: Scene, report: dict) -> None:
    """libsdformat's robot model against MuJoCo's compile of the robot at its placement: the same
    mass and centre of mass (so the link, inertial and model poses agree), a link per body."""
    from exporters.robot import compiled_robot
    from exporters.sdf_robot import CHAIN_LINK_MASS_KG, MODEL_NAME, robot_mass_kg

    m, d = compiled_robot(scene.robot, "SDF")
    got = next((mdl for mdl in report["models"] if mdl["name"] == MODEL_NAME), None)
    if got is None or len(got["links"]) < m.nbody - 1:
        raise ExportError(f"{path.name}: libsdformat finds no robot model with a link per body of the robot")
    mass = np.array([link["mass"] for link in got["links"]])
    if not np.isclose(mass.sum(), robot_mass_kg(m), rtol=1e-6):
        raise ExportError(f"{path.name}: libsdformat reads {mass.sum():.6g} kg of robot, MuJoCo {robot_mass_kg(m):.6g} kg")
    # Bodies at their inertial frames, chain links (a body's extra joints) at the body's origin.
    weights = [max(float(m.body_mass[b]), 1e-6) for b in range(1, m.nbody)]
    points = [d.xipos[b] for b in range(1, m.nbody)]
    for b in range(1, m.nbody):
        weights += [CHAIN_LINK_MASS_KG] * max(int(m.body_jntnum[b]) - 1, 0)
        points += [d.xpos[b]] * max(int(m.body_jntnum[b]) - 1, 0)
    t = scene.robot.world_from_robot
    want = (np.array(weights) @ np.array(points)) / sum(weights) @ t[:3, :3].T + t[:3, 3]
    got_com = (mass @ np.array([link["com"] for link in got["links"]])) / mass.sum()
    if np.linalg.norm(got_com - want) > 1e-4:
        raise ExportError(f"{path.name}: the robot's centre of mass is at {np.round(got_com, 4).tolist()} in libsdformat, "
                          f"{np.round(want, 4).tolist()} in MuJoCo")


def _positive(text: str | None) -> bool:
    try:
        return text is not None and float(text) > 0
    except ValueError:
        return False


def structural_problems(path: Path) -> list[str]:
    """What is structurally wrong with an SDF file (no SDFormat library needed): XML, version
    >= 1.9, one world with gravity, every non-static link's inertial, joints between known
    links, every mesh and texture a relative path to a file inside the folder. Empty when fine."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as err:
        return [f"not readable XML: {err}"]
    problems: list[str] = []
    try:
        version = tuple(int(v) for v in root.get("version", "").split("."))
    except ValueError:
        version = ()
    if root.tag != "sdf" or not (2, 0) > version >= (1, 9):
        problems.append(f"root is <{root.tag} version={root.get('version')!r}>, not <sdf version=\"1.9\"> or later 1.x")
    worlds = root.findall("world")
    if len(worlds) != 1:
        return problems + [f"expected one <world>, found {len(worlds)}"]
    if worlds[0].find("gravity") is None:
        problems.append("the world has no <gravity>")
    for model in worlds[0].iter("model"):
        mname = model.get("name")
        static = (model.findtext("static") or "false").strip() in ("true", "1")
        links = [link.get("name") for link in model.findall("link")]
        if not links or not mname:
            problems.append(f"model {mname!r} has no name or no link")
        for link in model.findall("link"):
            if not static and link.find("sensor") is None and not _positive(link.findtext("inertial/mass")):
                problems.append(f"link {mname}::{link.get('name')} of a moving model has no positive <inertial><mass>")
        for joint in model.findall("joint"):
            parent, child = joint.findtext("parent"), joint.findtext("child")
            if parent not in links + ["world"] or child not in links:
                problems.append(f"joint {mname}::{joint.get('name')} joins {parent!r} to {child!r}, not links of its model")
    folder = path.parent.resolve()
    for el in list(root.iter("uri")) + list(root.iter("albedo_map")):
        ref = (el.text or "").strip()
        target = (folder / ref).resolve()
        if "://" in ref or not target.is_relative_to(folder) or not target.is_file():
            problems.append(f"<{el.tag}> {ref!r} is not a file inside the output folder")
    return problems
