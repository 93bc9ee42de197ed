"""The robot (``Scene.robot``) as the exporters write it: its own MJCF, attached with MjSpec.

The robot's model is read from its file (Menagerie's or the built-in one), its mesh and texture
files are copied beside the scene's (``meshes/robot/``, ``textures/robot/``) so the output folder
stands alone, and it is attached at its placement under a frame with the prefix ``robot/``: its
bodies, joints, actuators, sensors and keyframes keep their names behind that prefix (Menagerie's
``home`` becomes the scene keyframe ``robot/home``, the rest of the scene at its start pose).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from exporters.textures import TEXTURE_DIR
from scene_builder.errors import ExportError
from scene_builder.robot import RobotPlacement

PREFIX = "robot/"
MESH_DIR = "meshes"
SUBDIR = "robot"


def _copy(src: Path, dst: Path) -> None:
    if not src.is_file():
        raise ExportError(f"robot model file {src} is missing; clear the Menagerie cache (MENAGERIE_CACHE_DIR) and build again")
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)


def _rel(name: str) -> str:
    """A file name from the robot's MJCF as a relative path below ``robot/`` (no ``..``)."""
    parts = [p for p in Path(name).parts if p not in ("", ".", "..", "/")]
    if not parts:
        raise ExportError(f"robot model names an empty file {name!r}")
    return "/".join([SUBDIR, *parts])


def robot_child_spec(placement: RobotPlacement, out_dir: Path):
    """The robot's ``MjSpec`` with its files copied under ``out_dir`` and paths rewritten to
    resolve against the scene's ``meshes/`` and ``textures/`` folders."""
    import mujoco

    src = Path(placement.model.mjcf_path)
    try:
        child = mujoco.MjSpec.from_file(str(src))
    except ValueError as err:
        raise ExportError(f"MuJoCo cannot read the robot model {src}: {str(err).strip().splitlines()[0]}") from err
    base = src.parent
    for assets, folder, out_folder in ((child.meshes, child.meshdir, MESH_DIR), (child.textures, child.texturedir, TEXTURE_DIR)):
        root = base / folder if folder else base
        for asset in assets:
            if asset.file:
                rel = _rel(asset.file)
                _copy(root / asset.file, Path(out_dir) / out_folder / rel)
                asset.file = rel
    if len(child.hfields) or len(child.skins):
        raise ExportError(f"robot model {src.name} uses height fields or skins, which the scene export does not carry")
    child.meshdir, child.texturedir = MESH_DIR, TEXTURE_DIR
    child.nkey = 0  # the size hint of a written file; the scene's keyframes are sized by the compiler
    child.modelfiledir = str(Path(out_dir).resolve())
    return child


def attach_robot(spec, placement: RobotPlacement, out_dir: Path) -> None:
    """Attach the robot to ``spec``'s world body at ``placement`` with the prefix ``robot/``."""
    child = robot_child_spec(placement, out_dir)
    yaw = float(placement.yaw_rad)
    frame = spec.worldbody.add_frame(pos=placement.position_m.tolist(), quat=[float(np.cos(yaw / 2)), 0.0, 0.0, float(np.sin(yaw / 2))])
    spec.attach(child, prefix=PREFIX, frame=frame)


# ---------------------------------------------------------------------------------------------
# The robot's own compiled model, as the USD and SDF writers read it
# ---------------------------------------------------------------------------------------------


def compiled_robot(placement: RobotPlacement, target: str):
    """(model, data at qpos0 after kinematics) of the robot's own MJCF; ``target`` names the
    export in the error when MuJoCo cannot load it."""
    import mujoco

    try:
        m = mujoco.MjModel.from_xml_path(str(placement.model.mjcf_path))
    except ValueError as err:
        raise ExportError(f"{target} export: MuJoCo cannot load the robot model: {str(err).strip().splitlines()[0]}") from err
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    return m, d


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of a MuJoCo quaternion (w, x, y, z)."""
    import mujoco

    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(q, dtype=np.float64))
    return out.reshape(3, 3)


def position_drives(m) -> dict[int, tuple[float, float, float, float]]:
    """joint id -> (kp, kv, max force (0: none), target at zero control) of its position
    actuator; joints coupled to a driven one by an equality (the second finger) get the same."""
    import mujoco

    out = {}
    for a in range(m.nu):
        if int(m.actuator_trntype[a]) != int(mujoco.mjtTrn.mjTRN_JOINT) or int(m.actuator_biastype[a]) != int(mujoco.mjtBias.mjBIAS_AFFINE):
            continue
        j = int(m.actuator_trnid[a, 0])
        force = float(np.max(np.abs(m.actuator_forcerange[a]))) if m.actuator_forcelimited[a] else 0.0
        target = float(np.clip(0.0, *m.jnt_range[j])) if m.jnt_limited[j] else 0.0
        out[j] = (float(m.actuator_gainprm[a, 0]), -float(m.actuator_biasprm[a, 2]), force, target)
    for e in range(m.neq):
        if int(m.eq_type[e]) == int(mujoco.mjtEq.mjEQ_JOINT):
            j1, j2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
            if j1 in out and j2 not in out:
                out[j2] = out[j1]
    return out
