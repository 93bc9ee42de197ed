"""URDF export: one URDF per object, ``urdf/<object>.urdf`` (:func:`write_object_urdfs`, the
default), and optionally the whole scene as ``scene.urdf``, one tree rooted at a ``world`` link
(:func:`write_urdf`, ``build --scene-urdf``).

* Per-object files are what URDF tools expect (many reject ``floating`` joints and a ``world``
  link): the object's links and joints as below, in the asset frame, root link first; the
  background is ``urdf/background.urdf``; ``urdf/placements.json`` gives each file's world pose.
* In ``scene.urdf`` every object's root part is a link named ``NAME`` attached to ``world`` by a ``floating``
  joint ``NAME/free`` (free objects) or a ``fixed`` joint ``NAME/fixed`` (fixed furniture), at
  ``world_from_asset``. Other parts are links ``NAME/PART`` under their parent by
  ``revolute`` / ``prismatic`` / ``fixed`` / ``floating`` joints named ``NAME/PART/joint``.
* URDF rotates a revolute joint about an axis through the joint frame's origin, so a part's
  link frame sits at its joint anchor (asset-frame axes); visual, collision and inertial origins
  are offset by minus the anchor. A revolute-prismatic joint has no URDF equivalent: it becomes
  a revolute joint plus a prismatic joint through a massless intermediate link, as URDF users do.
  URDF has no ball joint: ball (and free) joints inside an object are refused with ExportError.
  URDF has no joint spring either: a door hinged at its bottom keeps its damping and friction
  (``dynamics``) but not its counterbalance spring, which the MJCF, SDF and USD carry.
* Inertials: mass, origin at the centre of mass, full inertia tensor in link axes.
* Meshes: the same .obj files as the MJCF (``meshes/``, relative paths; textured ones name their
  photo texture in a .mtl beside them). A ``<mujoco>`` extension element tells MuJoCo's URDF
  importer to keep the relative paths and the visual geoms.
* The static background is a link ``background`` welded to ``world`` (joint ``background/fixed``):
  its textured surface and the objects that became background as visuals, their convex pieces
  and the background's collision boxes as collisions. It has a nominal 1 kg inertial (URDF
  consumers reject a link without mass); it cannot move.

Validated by parsing with MuJoCo's URDF importer and with yourdfpy (tests).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from exporters import names
from exporters.mjcf import MESH_DIR, background_meshes, mesh_files, part_rgba, write_part_meshes
from exporters.textures import TEXTURE_DIR, texture_file
from scene_builder.errors import ExportError
from scene_builder.model import Background, JointType, ObjectAsset, Part, PlacedObject, Room, Scene


def _fmt(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.atleast_1d(values))


def rpy_from_matrix(r: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw (fixed axes X, Y, Z: ``R = Rz(yaw) Ry(pitch) Rx(roll)``) of a rotation.
    At pitch +-90 deg (a robot link turned onto its side) roll and yaw are not unique: scipy
    sets yaw to zero and warns; the angles still give ``r`` exactly, so the warning is dropped."""
    import warnings

    from scipy.spatial.transform import Rotation

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Gimbal lock detected")
        return Rotation.from_matrix(r).as_euler("xyz")


def write_urdf(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.urdf`` (meshes under ``out_dir/meshes``), load it with MuJoCo's URDF
    importer and raise :class:`ExportError` naming the object when it is rejected."""
    out_dir = Path(out_dir)
    robot = _robot("scene")
    ET.SubElement(robot, "link", name="world")
    if scene.room.background is not None:
        _add_background(robot, scene.room.background, out_dir)
    # URDF has no soft bodies: a deformable is exported as its rigid shape (its mass and meshes).
    for placed in scene.objects:
        write_part_meshes(placed.asset, out_dir)
        _add_object(robot, placed)
    path = _write(robot, out_dir / "scene.urdf")
    validate_urdf(path, scene)
    return path


#: Folder of the per-object URDFs, inside the output folder.
URDF_DIR = "urdf"
PLACEMENTS_FILE = "placements.json"


def _robot(name: str) -> ET.Element:
    robot = ET.Element("robot", name=name)
    mj = ET.SubElement(robot, "mujoco")
    ET.SubElement(mj, "compiler", discardvisual="false", strippath="false", fusestatic="false", balanceinertia="false")
    return robot


def _write(robot: ET.Element, path: Path) -> Path:
    ET.indent(robot)
    path.write_text('<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n")
    return path


def object_urdf_files(scene: Scene) -> dict[str, str]:
    """File name (under ``urdf/``) of every object's URDF: object name -> ``<file_stem>.urdf``."""
    return {placed.name: names.file_stem(placed.name) + ".urdf" for placed in scene.objects}


def write_object_urdfs(scene: Scene, out_dir: Path) -> Path:
    """Write one URDF per object, ``out_dir/urdf/<object>.urdf``, the form most URDF consumers
    expect (one robot, its root link first, no ``world`` link and no ``floating`` joint):
    links and joints as in ``scene.urdf``, in the asset frame. The static background, when there
    is one, is ``urdf/background.urdf`` (one link). ``urdf/placements.json`` gives each file's
    pose in the world (``position_m``, ``quat_wxyz``, ``rpy_rad``) and whether it is welded
    there (``fixed``). Meshes and textures are the shared ``meshes/`` and ``textures/`` files
    (``../`` relative paths). Each file is loaded with MuJoCo's URDF importer; returns the folder."""
    from scene_builder.frames import quat_wxyz_from_matrix

    out_dir = Path(out_dir)
    folder = out_dir / URDF_DIR
    folder.mkdir(parents=True, exist_ok=True)
    placements = []
    files = object_urdf_files(scene)
    for placed in scene.objects:
        write_part_meshes(placed.asset, out_dir)
        robot = _robot(placed.name)
        _add_object(robot, placed.asset, up="../")
        path = _write(robot, folder / files[placed.name])
        validate_urdf(path, Scene(scene.camera, Room(), (placed,)))
        t = placed.world_from_asset
        placements.append({
            "name": placed.name, "urdf": files[placed.name], "fixed": bool(placed.asset.is_fixed),
            "position_m": t[:3, 3].tolist(), "quat_wxyz": quat_wxyz_from_matrix(t[:3, :3]).tolist(),
            "rpy_rad": rpy_from_matrix(t[:3, :3]).tolist(),
        })
    doc = {"format": "scene-builder/urdf-placements", "version": 1, "objects": placements, "background": None}
    if scene.room.background is not None:
        robot = _robot("background")
        _add_background(robot, scene.room.background, out_dir, up="../", weld=False)
        validate_urdf(_write(robot, folder / "background.urdf"), Scene(scene.camera, Room(), ()))
        doc["background"] = "background.urdf"
    (folder / PLACEMENTS_FILE).write_text(json.dumps(doc, indent=1) + "\n")
    return folder


def _origin(parent: ET.Element, xyz, rpy=(0.0, 0.0, 0.0)) -> None:
    ET.SubElement(parent, "origin", xyz=_fmt(xyz), rpy=_fmt(rpy))


def _link(robot: ET.Element, asset: ObjectAsset, part: Part, frame_m: np.ndarray, up: str = "") -> None:
    """A link whose frame is at ``frame_m`` (asset frame point) with asset-frame axes. ``up``: the
    output folder seen from the URDF file (``""`` or ``"../"``), the prefix of mesh and texture paths."""
    link = ET.SubElement(robot, "link", name=names.body_name(asset, part))
    inertial = ET.SubElement(link, "inertial")
    _origin(inertial, part.inertial.com_m - frame_m)
    ET.SubElement(inertial, "mass", value=f"{part.inertial.mass_kg:.9g}")
    i = part.inertial.inertia_kg_m2
    ET.SubElement(inertial, "inertia", ixx=f"{i[0, 0]:.9g}", ixy=f"{i[0, 1]:.9g}", ixz=f"{i[0, 2]:.9g}",
                  iyy=f"{i[1, 1]:.9g}", iyz=f"{i[1, 2]:.9g}", izz=f"{i[2, 2]:.9g}")
    vis_file, col_files = mesh_files(asset, part)
    visual = ET.SubElement(link, "visual", name=f"{names.body_name(asset, part)}/visual")
    _origin(visual, -frame_m)
    ET.SubElement(ET.SubElement(visual, "geometry"), "mesh", filename=f"{up}{MESH_DIR}/{vis_file}")
    mat = ET.SubElement(visual, "material", name=f"{asset.name}/{part.name}/{part.material.name}")
    ET.SubElement(mat, "color", rgba=_fmt(part_rgba(part)))
    if part.visual.texture is not None:
        ET.SubElement(mat, "texture", filename=f"{up}{TEXTURE_DIR}/{texture_file(part.visual.texture)}")
    for k, fname in enumerate(col_files):
        col = ET.SubElement(link, "collision", name=f"{names.body_name(asset, part)}/collision_{k}")
        _origin(col, -frame_m)
        ET.SubElement(ET.SubElement(col, "geometry"), "mesh", filename=f"{up}{MESH_DIR}/{fname}")


def _add_background(robot: ET.Element, bg: Background, out_dir: Path, up: str = "", weld: bool = True) -> None:
    """The ``background`` link (and, with ``weld``, its fixed joint to ``world``)."""
    visuals, pieces = background_meshes(bg, out_dir)
    link = ET.SubElement(robot, "link", name="background")
    inertial = ET.SubElement(link, "inertial")
    _origin(inertial, (0.0, 0.0, 0.0))
    ET.SubElement(inertial, "mass", value="1")
    ET.SubElement(inertial, "inertia", ixx="1", ixy="0", ixz="0", iyy="1", iyz="0", izz="1")
    for name, fname, mesh in visuals:
        visual = ET.SubElement(link, "visual", name=name)
        _origin(visual, (0.0, 0.0, 0.0))
        ET.SubElement(ET.SubElement(visual, "geometry"), "mesh", filename=f"{up}{MESH_DIR}/{fname}")
        mat = ET.SubElement(visual, "material", name=f"{name}/material")
        if mesh.texture is not None:
            ET.SubElement(mat, "texture", filename=f"{up}{TEXTURE_DIR}/{texture_file(mesh.texture)}")
        else:
            ET.SubElement(mat, "color", rgba="0.7 0.7 0.7 1")
    for k, fname in enumerate(pieces):
        col = ET.SubElement(link, "collision", name=f"background/piece/{k}")
        _origin(col, (0.0, 0.0, 0.0))
        ET.SubElement(ET.SubElement(col, "geometry"), "mesh", filename=f"{up}{MESH_DIR}/{fname}")
    for k in range(bg.box_count):
        col = ET.SubElement(link, "collision", name=f"background/box/{k}")
        _origin(col, bg.box_centers_m[k], (0.0, 0.0, float(bg.box_yaws_rad[k])))
        ET.SubElement(ET.SubElement(col, "geometry"), "box", size=_fmt(2.0 * bg.box_half_extents_m[k]))
    if not weld:
        return
    j = ET.SubElement(robot, "joint", name="background/fixed", type="fixed")
    _origin(j, (0.0, 0.0, 0.0))
    ET.SubElement(j, "parent", link="world")
    ET.SubElement(j, "child", link="background")


def _add_object(robot: ET.Element, placed: PlacedObject | ObjectAsset, up: str = "") -> None:
    """The links and joints of an object. A :class:`PlacedObject` is attached to ``world`` at its
    pose (``floating``, or ``fixed`` for fixed furniture); a bare :class:`ObjectAsset` is not (its
    root link is the tree's root: the per-object URDF)."""
    asset = placed.asset if isinstance(placed, PlacedObject) else placed
    frames = {p.name: (np.zeros(3) if p.joint is None else p.joint.anchor_m) for p in asset.parts}
    _link(robot, asset, asset.root, frames[asset.root.name], up)
    if isinstance(placed, PlacedObject):
        t = placed.world_from_asset
        kind = "fixed" if asset.is_fixed else "floating"
        jname = f"{asset.name}/fixed" if asset.is_fixed else names.free_joint_name(asset)
        j = ET.SubElement(robot, "joint", name=jname, type=kind)
        _origin(j, t[:3, 3], rpy_from_matrix(t[:3, :3]))
        ET.SubElement(j, "parent", link="world")
        ET.SubElement(j, "child", link=asset.name)
    for part in asset.parts:
        if part.joint is None:
            continue
        _link(robot, asset, part, frames[part.name], up)
        _add_joint(robot, asset, part, frames[part.parent] if part.parent else np.zeros(3))


def _add_joint(robot: ET.Element, asset: ObjectAsset, part: Part, parent_frame: np.ndarray) -> None:
    jt = part.joint
    assert jt is not None and part.parent is not None
    parent = names.body_name(asset, next(p for p in asset.parts if p.name == part.parent))
    child = names.body_name(asset, part)
    offset = jt.anchor_m - parent_frame

    def joint(name: str, kind: str, parent_link: str, child_link: str, xyz, lo: float, hi: float) -> None:
        j = ET.SubElement(robot, "joint", name=name, type=kind)
        _origin(j, xyz)
        ET.SubElement(j, "parent", link=parent_link)
        ET.SubElement(j, "child", link=child_link)
        if kind in ("revolute", "prismatic"):
            ET.SubElement(j, "axis", xyz=_fmt(jt.axis))
            ET.SubElement(j, "limit", lower=f"{lo:.9g}", upper=f"{hi:.9g}", effort=f"{jt.effort_limit:.9g}", velocity="10")
            ET.SubElement(j, "dynamics", damping=f"{jt.damping:.9g}", friction=f"{jt.friction:.9g}")

    if jt.type is JointType.REVOLUTE:
        joint(names.joint_name(asset, part), "revolute", parent, child, offset, jt.lower, jt.upper)
    elif jt.type is JointType.PRISMATIC:
        joint(names.joint_name(asset, part), "prismatic", parent, child, offset, jt.lower, jt.upper)
    elif jt.type is JointType.FIXED:
        joint(names.joint_name(asset, part), "fixed", parent, child, offset, 0.0, 0.0)
    elif jt.type is JointType.REVOLUTE_PRISMATIC:
        mid = f"{child}/slide"
        link = ET.SubElement(robot, "link", name=mid)
        inertial = ET.SubElement(link, "inertial")
        _origin(inertial, (0.0, 0.0, 0.0))
        # MuJoCo and most URDF consumers reject a zero mass on a moving link: 1 g, 1e-9 inertia.
        ET.SubElement(inertial, "mass", value="0.001")
        ET.SubElement(inertial, "inertia", ixx="1e-9", ixy="0", ixz="0", iyy="1e-9", iyz="0", izz="1e-9")
        joint(names.joint_name(asset, part, "_slide"), "prismatic", parent, mid, offset, jt.lower2, jt.upper2)
        joint(names.joint_name(asset, part), "revolute", mid, child, np.zeros(3), jt.lower, jt.upper)
    else:
        raise ExportError(f"object {asset.name}: part {part.name} has a {jt.type.value} joint, which URDF cannot express; make it a separate object")


def validate_urdf(path: Path, scene: Scene) -> None:
    """Load the URDF with MuJoCo's importer (which resolves every mesh) and check that every
    object's links are there; a per-object URDF (no ``world`` link) must have no ``floating`` joint."""
    import mujoco

    root = ET.parse(path).getroot()
    if root.find("link[@name='world']") is None and root.find("joint[@type='floating']") is not None:
        raise ExportError(f"{path.name} has a floating joint, which most URDF consumers reject")

    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except ValueError as err:
        msg = str(err).strip().splitlines()[0]
        who = next((o.name for o in scene.objects if o.name in str(err)), None)
        raise ExportError(f"MuJoCo's URDF importer rejects {path.name}" + (f" at object {who}" if who else "") + f": {msg}") from err
    for placed in scene.objects:
        for part in placed.asset.parts:
            if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, names.body_name(placed.asset, part)) < 0:
                raise ExportError(f"URDF of object {placed.name}: link {names.body_name(placed.asset, part)} is missing after import")
