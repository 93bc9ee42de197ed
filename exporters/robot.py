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
