"""The robot of ``--robot NAME``: MuJoCo Menagerie when it can be had, else the built-in model.

Sources, in order (``source="auto"``):

* ``menagerie``: the ``mujoco-menagerie`` package's registry names the model directory and the
  checksum of its archive; ``Robot.path(cache)`` downloads it once from Menagerie's release
  assets into its cache (``MENAGERIE_CACHE_DIR``; ``MENAGERIE_BASE_URL`` for a mirror,
  ``MENAGERIE_ROOT`` for a local checkout) and verifies the SHA-256 before unpacking.
* ``built-in``: :mod:`generation.robot_builtin` (offline; Franka Panda from its published
  kinematics and masses), written as ``robot.xml`` into the folder the caller gives.

``offline`` skips the download. Whichever answered is in :attr:`RobotModel.source` and
:attr:`RobotModel.detail` (and so in report.json). Every figure the layout uses (footprint,
height, shoulder, reach) is measured here on the compiled model, whatever the source.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.robot import RobotModel

SOURCES = ("auto", "menagerie", "built-in")
REACH_SAMPLES = 2000


@dataclass(frozen=True)
class RobotEntry:
    """One ``--robot`` name. menagerie: (registry name, entry point) or None; builtin: whether
    :mod:`generation.robot_builtin` has it. ee_body / tcp_m: where the loader adds site ``tcp``
    when the model has no site called ``ee_site``."""

    menagerie: tuple[str, str] | None
    builtin: bool
    ee_site: str = "tcp"
    ee_body: str = "hand"
    tcp_m: tuple[float, float, float] = (0.0, 0.0, 0.1034)
    description: str = ""


ROBOTS: dict[str, RobotEntry] = {
    "panda": RobotEntry(("franka_emika_panda", "panda"), True, description="Franka Emika Panda arm, fixed base"),
    "mobile_panda": RobotEntry(None, True, description="Franka Panda on a holonomic base (built-in only)"),
    "tidybot": RobotEntry(("stanford_tidybot", "tidybot"), False, ee_site="pinch_site", ee_body="bracelet_link",
                          tcp_m=(0.0, 0.0, -0.17), description="Stanford TidyBot: holonomic base, Kinova Gen3 arm (Menagerie only)"),
}


def robot_names() -> tuple[str, ...]:
    return tuple(sorted(ROBOTS))


def load_robot(name: str, work_dir: Path, source: str = "auto", offline: bool = False, cache=None) -> RobotModel:
    """The robot called ``name`` from the first source that answers (see the module docstring).

    work_dir: where the built-in model's ``robot.xml`` is written. cache: a
    ``mujoco_menagerie.Cache`` (default: the package's, from its environment variables).
    Raises InputError for an unknown name or source, ModelUnavailableError when the only source
    asked for cannot answer.
    """
    check_robot_request(name, source, offline)
    entry = ROBOTS[name]
    why = ""
    if source in ("auto", "menagerie") and entry.menagerie is not None:
        import mujoco_menagerie

        try:
            return _from_menagerie(name, entry, Path(work_dir), cache, download=not offline)
        except (mujoco_menagerie.MenagerieError, OSError, ModelUnavailableError) as err:  # reported, then the fallback
            if source == "menagerie" or not entry.builtin:
                raise ModelUnavailableError(
                    f"robot {name}: MuJoCo Menagerie's {entry.menagerie[0]} is not available ({_one_line(err)}); "
                    "connect to the network, set MENAGERIE_ROOT to a Menagerie checkout"
                    + (", or pass --robot-source built-in" if entry.builtin else "")
                ) from err
            why = f"Menagerie unavailable: {_one_line(err)}"
    return _from_builtin(name, entry, Path(work_dir), why)


def check_robot_request(name: str, source: str = "auto", offline: bool = False) -> None:
    """Raise InputError (one line) unless ``name`` from ``source`` can be asked for at all; the
    pipeline calls it before the slow stages."""
    if name not in ROBOTS:
        raise InputError(f"unknown robot {name!r}; choose one of {', '.join(robot_names())}")
    if source not in SOURCES:
        raise InputError(f"unknown robot source {source!r}; choose one of {', '.join(SOURCES)}")
    entry = ROBOTS[name]
    if source == "menagerie" and entry.menagerie is None:
        raise InputError(f"robot {name} is not in MuJoCo Menagerie; pass --robot-source built-in (or auto)")
    if source == "built-in" and not entry.builtin:
        raise InputError(f"robot {name} has no built-in model (MuJoCo Menagerie only); pass --robot-source auto")


def _one_line(err: Exception) -> str:
    text = str(err).strip().splitlines()
    return (text[0] if text else type(err).__name__)[:200]


def _from_menagerie(name: str, entry: RobotEntry, work_dir: Path, cache, download: bool = True) -> RobotModel:
    import mujoco_menagerie

    registry_name, entry_point = entry.menagerie
    robot = mujoco_menagerie.get(registry_name)
    cache = cache or mujoco_menagerie.Cache()
    if not download and cache.root is None and not cache.is_cached(robot):
        raise ModelUnavailableError(f"offline and {registry_name} is not in the Menagerie cache {cache.dir}")
    folder = robot.path(cache, progress=None)
    xml = folder / robot.entry(entry_point).file
    detail = (f"MuJoCo Menagerie {registry_name} ({robot.display_name}, licence {robot.license}, "
              f"commit {mujoco_menagerie.commit()[:12]}, model {robot.oid[:12]})")
    return measure_robot(name, "menagerie", detail, _prepared(xml, entry, work_dir), entry)


def _from_builtin(name: str, entry: RobotEntry, work_dir: Path, why: str) -> RobotModel:
    from generation.robot_builtin import BUILDERS

    spec = BUILDERS[name]()
    work_dir.mkdir(parents=True, exist_ok=True)
    xml = work_dir / "robot.xml"
    _ensure_site(spec, entry)
    xml.write_text(spec.to_xml())
    detail = "built-in: Franka Panda from Franka's published DH table, joint limits and link masses (capsule geometry)"
    if name == "mobile_panda":
        detail += ", on a holonomic base (planar x, y, yaw joints)"
    if why:
        detail += f"; {why}"
    return measure_robot(name, "built-in", detail, xml, entry)


def _prepared(xml: Path, entry: RobotEntry, work_dir: Path) -> Path:
    """``work_dir/robot.xml``: the model as the exporters attach it, the file as loaded plus
    site ``tcp`` on the end-effector body when it has no ``ee_site`` of its own; its mesh and
    texture folders point back at the model's own folder (absolute), which stays untouched."""
    import mujoco

    spec = mujoco.MjSpec.from_file(str(xml))
    _ensure_site(spec, entry)
    spec.meshdir = str((xml.parent / spec.meshdir).resolve())
    spec.texturedir = str((xml.parent / spec.texturedir).resolve())
    work_dir.mkdir(parents=True, exist_ok=True)
    out = work_dir / "robot.xml"
    out.write_text(spec.to_xml())
    return out


def _ensure_site(spec, entry: RobotEntry) -> None:
    if spec.site(entry.ee_site) is not None:
        return
    body = spec.body(entry.ee_body)
    if body is None:
        raise ModelUnavailableError(f"robot model has neither site {entry.ee_site!r} nor body {entry.ee_body!r}; its MJCF changed")
    body.add_site(name=entry.ee_site, pos=list(entry.tcp_m), size=[0.01, 0, 0], group=4)


def _chain_joints(m, body: int) -> list[int]:
    """Joint ids from the root to ``body``, root first."""
    out = []
    while body > 0:
        adr, num = int(m.body_jntadr[body]), int(m.body_jntnum[body])
        out = list(range(adr, adr + num)) + out
        body = int(m.body_parentid[body])
    return out


def measure_robot(name: str, source: str, detail: str, xml: Path, entry: RobotEntry) -> RobotModel:
    """Compile the robot alone and measure what the layout needs (see :class:`RobotModel`).

    Base joints: the chain to the tool site up to its last slide joint and the joints of that
    slide's body (a planar x, y, yaw base); the rest of the chain is the arm. Reach: over
    REACH_SAMPLES uniform joint samples within the limits (seed 0), the farthest tool position
    from the shoulder."""
    import mujoco

    spec = mujoco.MjSpec.from_file(str(xml))
    try:
        m = spec.compile()
    except ValueError as err:
        raise ModelUnavailableError(f"robot {name}: MuJoCo rejects {xml}: {_one_line(err)}") from err
    site = m.site(entry.ee_site).id
    chain = [j for j in _chain_joints(m, int(m.site_bodyid[site])) if int(m.jnt_type[j]) in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))]
    slides = [k for k, j in enumerate(chain) if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_SLIDE)]
    n_base = 0
    if slides:
        last_body = int(m.jnt_bodyid[chain[slides[-1]]])
        n_base = max(k for k, j in enumerate(chain) if k <= slides[-1] or int(m.jnt_bodyid[j]) == last_body) + 1
    base, arm = chain[:n_base], chain[n_base:]
    if not arm:
        raise ModelUnavailableError(f"robot {name}: no arm joints between the base and site {entry.ee_site}")
    d = mujoco.MjData(m)
    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home")
    if key >= 0:
        mujoco.mj_resetDataKeyframe(m, d, key)
    mujoco.mj_forward(m, d)
    home = np.array([d.qpos[m.jnt_qposadr[j]] for j in arm])
    for k, j in enumerate(arm):
        if m.jnt_limited[j]:
            home[k] = np.clip(home[k], *m.jnt_range[j])
    # Footprint and height of the collision geometry at the start pose (qpos0, how the scene
    # starts; robot frame = world here). The home pose is checked in the scene by layout.reach.
    mujoco.mj_resetData(m, d)
    mujoco.mj_forward(m, d)
    geoms = np.flatnonzero((m.geom_contype != 0) | (m.geom_conaffinity != 0))
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    corners = np.concatenate([
        (m.geom_aabb[g, :3] + signs * m.geom_aabb[g, 3:]) @ d.geom_xmat[g].reshape(3, 3).T + d.geom_xpos[g] for g in geoms
    ]) if len(geoms) else np.zeros((1, 3))
    footprint = float(np.linalg.norm(corners[:, :2], axis=1).max())
    height = float(corners[:, 2].max())
    shoulder = d.xanchor[arm[0]].copy()
    rng = np.random.default_rng(0)
    lo = np.array([m.jnt_range[j][0] if m.jnt_limited[j] else -np.pi for j in arm])
    hi = np.array([m.jnt_range[j][1] if m.jnt_limited[j] else np.pi for j in arm])
    adr = np.array([m.jnt_qposadr[j] for j in arm])
    reach = 0.0
    for q in rng.uniform(lo, hi, size=(REACH_SAMPLES, len(arm))):
        d.qpos[adr] = q
        mujoco.mj_kinematics(m, d)
        reach = max(reach, float(np.linalg.norm(d.site_xpos[site] - shoulder)))
    return RobotModel(
        name=name, source=source, detail=detail, mjcf_path=Path(xml), ee_site=entry.ee_site,
        arm_joints=tuple(m.joint(j).name for j in arm), base_joints=tuple(m.joint(j).name for j in base),
        home_qpos=home, footprint_radius_m=footprint, height_m=height, arm_mount_m=shoulder, reach_m=reach,
    )
