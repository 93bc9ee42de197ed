"""The robot of a scene (``--robot NAME``): the model as loaded and where the layout put it.

Frames and units follow :mod:`scene_builder.model` (world Z up, metres, radians). The robot's
own frame is the frame of its MJCF's world body: Z up, the arm's front along +X.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scene_builder.arrays import _freeze

__all__ = ["RobotModel", "RobotPlacement"]


@dataclass(frozen=True, eq=False)
class RobotModel:
    """A robot ready to be attached to a scene, measured from its compiled MJCF.

    name: the ``--robot`` name (``panda``, ``mobile_panda``, ``tidybot``). source: which source
      answered: ``"menagerie"`` (MuJoCo Menagerie through the ``mujoco-menagerie`` package) or
      ``"built-in"`` (built offline with MjSpec from published kinematics). detail: one line
      for report.json (Menagerie name, commit and licence, or the parameters' origin).
    mjcf_path: the robot's MJCF file; mesh and texture files resolve against its folder.
    ee_site: the site at the tool centre point (added by the loader when the model has none).
    arm_joints / base_joints: joint names (in the robot's own MJCF, without prefix) of the arm
      and of the mobile base (empty for a fixed base). home_qpos: (len(arm_joints),) arm pose
      for the start of a task (within the joint limits).
    footprint_radius_m: radius around the robot frame's origin of its collision geometry
      projected onto the floor at the start pose (qpos0). height_m: top of that geometry.
    arm_mount_m: (3,) first arm joint's position in the robot frame (the shoulder).
    reach_m: largest distance from the shoulder that the tool centre point reaches, sampled over
      the joint limits.
    """

    name: str
    source: str
    detail: str
    mjcf_path: Path
    ee_site: str
    arm_joints: tuple[str, ...]
    base_joints: tuple[str, ...]
    home_qpos: np.ndarray
    footprint_radius_m: float
    height_m: float
    arm_mount_m: np.ndarray
    reach_m: float

    def __post_init__(self) -> None:
        _freeze(self, "home_qpos", np.float64, (len(self.arm_joints),))
        _freeze(self, "arm_mount_m", np.float64, (3,))

    @property
    def mobile(self) -> bool:
        return bool(self.base_joints)


@dataclass(frozen=True, eq=False)
class RobotPlacement:
    """Where the layout stood the robot. position_m: (3,) robot frame origin in the world (on
    the floor); yaw_rad: heading about +Z (the robot's +X looks at the target).
    target_m: (3,) a point the arm should reach near ``target_support`` (an object's name, or
    ``background``); target_kind: ``"top"`` (above a flat top, a table's), ``"object_top"``
    (above a movable object's highest point) or ``"side"`` (beside a movable object, over open
    floor). clearance_m: distance from the robot's footprint to the nearest obstacle on the
    floor plan. hold_tool_axis: the scripted reach keeps the tool's approach axis as at the home
    pose (a gripper pointing down); False where the arm gets there only with it free (a high
    table at the edge of a floor-standing arm's reach)."""

    model: RobotModel
    position_m: np.ndarray
    yaw_rad: float
    target_m: np.ndarray
    target_support: str
    target_kind: str
    clearance_m: float
    hold_tool_axis: bool = True

    def __post_init__(self) -> None:
        _freeze(self, "position_m", np.float64, (3,))
        _freeze(self, "target_m", np.float64, (3,))

    @property
    def world_from_robot(self) -> np.ndarray:
        """(4, 4) transform of the robot frame."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        t = np.eye(4)
        t[:2, :2] = [[c, -s], [s, c]]
        t[:3, 3] = self.position_m
        return t
