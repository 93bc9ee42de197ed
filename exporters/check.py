"""``check_output``: re-open an output folder the way its consumers would and list the problems.

Checks: ``scene.xml`` compiles and steps stably for 1 s (finite state, no MuJoCo warnings, no
free body faster than ``MAX_SPEED_M_S``); ``scene.usda`` passes every registered UsdValidation
validator; every file referenced by the MJCF, URDFs (``scene.urdf``, ``urdf/*.urdf``), SDF and
USD exists inside the folder; no per-object URDF has a floating joint; ``scene.sdf`` passes the
structural check of :mod:`exporters.sdf` and libsdformat's when its checker is found;
``scene.glb`` loads; ``report.json`` (when present) has ``timings_s``, ``objects``,
``layout.max_penetration_m`` and ``layout.settle_max_drift_m`` and names the same objects as the
scene.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

CHECK_SECONDS = 1.0
# A built scene starts at rest. A free body faster than this at any time in the first second
# (a fall from 20 cm) or displaced more than MAX_DRIFT_M is being thrown out of a contact.
MAX_SPEED_M_S = 2.0
MAX_DRIFT_M = 0.1


def check_output(out_dir: Path) -> tuple[str, ...]:
    """Problems found in ``out_dir`` (one line each); empty when everything is fine."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        return (f"{out_dir} is not a folder",)
    problems: list[str] = []
    names = None
    if (out_dir / "scene.xml").exists():
        names = _check_mjcf(out_dir / "scene.xml", problems)
    else:
        problems.append("scene.xml is missing")
    if (out_dir / "scene.usda").exists():
        _check_usd(out_dir / "scene.usda", problems)
    if (out_dir / "scene.urdf").exists():
        _check_urdf(out_dir / "scene.urdf", problems)
    for path in sorted((out_dir / "urdf").glob("*.urdf")):
        _check_urdf(path, problems, per_object=True)
    if (out_dir / "scene.sdf").exists():
        _check_sdf(out_dir / "scene.sdf", problems)
    if (out_dir / "scene.glb").exists():
        _check_glb(out_dir / "scene.glb", problems)
    if (out_dir / "scene.json").exists():
        names = _check_scene_json(out_dir / "scene.json", names, problems)
    if (out_dir / "report.json").exists():
        _check_report(out_dir / "report.json", names, problems)
    return tuple(problems)


def _inside(out_dir: Path, ref: Path, what: str, problems: list[str]) -> None:
    try:
        resolved = ref.resolve()
        resolved.relative_to(out_dir.resolve())
    except ValueError:
        problems.append(f"{what} references {ref}, which is outside the output folder")
        return
    if not resolved.is_file():
        problems.append(f"{what} references {ref.relative_to(out_dir) if ref.is_relative_to(out_dir) else ref}, which does not exist")


def _check_mjcf(path: Path, problems: list[str]) -> list[str] | None:
    import mujoco

    root = ET.parse(path).getroot()
    compiler = root.find("compiler")
    # MuJoCo looks for meshes, height fields and skins in meshdir, textures in texturedir; assetdir sets both.
    assetdir = compiler.get("assetdir", "") if compiler is not None else ""
    meshdir = compiler.get("meshdir", assetdir) if compiler is not None else ""
    texturedir = compiler.get("texturedir", assetdir) if compiler is not None else ""
    for tag in ("mesh", "texture", "hfield", "skin"):
        folder = texturedir if tag == "texture" else meshdir
        for el in root.iter(tag):
            if el.get("file"):
                _inside(path.parent, path.parent / folder / el.get("file"), path.name, problems)
    if problems:
        return None
    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except ValueError as err:
        problems.append(f"{path.name} does not compile: {str(err).strip().splitlines()[0]}")
        return None
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    free_bodies = np.array([model.jnt_bodyid[i] for i in range(model.njnt) if model.jnt_type[i] == mujoco.mjtJoint.mjJNT_FREE], dtype=int)
    start = data.xpos[free_bodies].copy()
    max_speed = np.zeros(len(free_bodies))
    steps = int(round(CHECK_SECONDS / model.opt.timestep))
    for _ in range(steps):
        mujoco.mj_step(model, data)
        max_speed = np.fmax(max_speed, np.linalg.norm(data.cvel[free_bodies, 3:], axis=1))
    if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
        problems.append(f"{path.name}: simulation state is not finite after {CHECK_SECONDS:g} s")
    for w in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL):
        if data.warning[w].number > 0:
            problems.append(f"{path.name}: MuJoCo warning {w.name} after {CHECK_SECONDS:g} s of simulation")
    # Top-level bodies are the scene's objects; the robot (``--robot``) hangs below ``robot/``.
    top = [model.body(i).name for i in range(1, model.nbody) if model.body_parentid[i] == 0 and not model.body(i).name.startswith("robot/")]
    drift = np.linalg.norm(data.xpos[free_bodies] - start, axis=1)
    bad = [
        f"{model.body(b).name} (top speed {v:.2g} m/s, moved {d:.2g} m)"
        for b, v, d in zip(free_bodies, max_speed, drift)
        if not (v <= MAX_SPEED_M_S and d <= MAX_DRIFT_M)
    ]
    if bad:
        problems.append(f"{path.name}: unstable in the first {CHECK_SECONDS:g} s: {', '.join(bad)}")
    flex = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_FLEX, i) for i in range(model.nflex)]
    # Flex nodes are top-level bodies named after their flex: report objects, not nodes.
    return sorted([n for n in top if not any(n.startswith(f + "_") for f in flex)] + flex)


def _check_usd(path: Path, problems: list[str]) -> None:
    from pxr import Usd, UsdUtils

    from exporters.usd import validate_stage

    from pxr import Tf

    try:
        stage = Usd.Stage.Open(str(path))
    except Tf.ErrorException as err:  # what pxr raises for a layer it cannot read; a problem line
        problems.append(f"{path.name} does not open: {str(err).strip().splitlines()[0]}")
        return
    for msg in validate_stage(stage):
        problems.append(f"{path.name}: {msg}")
    layers, assets, unresolved = UsdUtils.ComputeAllDependencies(str(path))
    for a in list(assets) + [Path(u) for u in unresolved]:
        _inside(path.parent, path.parent / a, path.name, problems)
    if stage.GetDefaultPrim() is None or not stage.GetDefaultPrim().IsValid():
        problems.append(f"{path.name}: no default prim")


def _check_urdf(path: Path, problems: list[str], per_object: bool = False) -> None:
    """Every mesh a relative path to a file inside the output folder; a per-object URDF
    (``urdf/NAME.urdf``) has no ``floating`` joint."""
    out_dir = path.parent.parent if per_object else path.parent
    what = f"{path.parent.name}/{path.name}" if per_object else path.name
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        problems.append(f"{what} is not readable XML: {err}")
        return
    for el in root.iter("mesh"):
        name = el.get("filename", "")
        if name.startswith("package://") or name.startswith("file://"):
            problems.append(f"{what} references {name}: use paths relative to the folder")
            continue
        _inside(out_dir, path.parent / name, what, problems)
    if per_object and any(j.get("type") == "floating" for j in root.iter("joint")):
        problems.append(f"{what} has a floating joint, which most URDF consumers reject")


def _check_sdf(path: Path, problems: list[str]) -> None:
    """The structural check of :mod:`exporters.sdf`, then libsdformat's when its checker is found."""
    from exporters.sdf import run_checker, structural_problems
    from scene_builder.errors import ExportError

    found = structural_problems(path)
    problems.extend(f"{path.name}: {p}" for p in found)
    if found:
        return
    try:
        run_checker(path)
    except ExportError as err:
        problems.append(str(err))


#: What ``trimesh.load`` raises for a .glb it cannot read. trimesh documents none; these are the
#: types its glTF loader raised on 3,306 corrupted copies of two small scenes (byte changes,
#: deletions, insertions, truncations; ``tests/test_export_check.py`` repeats a few hundred):
#: ValueError 2,921 (JSONDecodeError among them), KeyError 83, NotImplementedError 32, IndexError
#: 7, UnboundLocalError 4 (a bug of its loader), and OSError for a file that cannot be read.
#: Caught around that one call only.
GLB_LOAD_ERRORS: tuple[type[BaseException], ...] = (OSError, ValueError, KeyError, IndexError, NotImplementedError, UnboundLocalError)


def _check_glb(path: Path, problems: list[str]) -> None:
    import trimesh

    try:
        scene = trimesh.load(str(path), force="scene")
    except GLB_LOAD_ERRORS as err:  # a file that does not load is a problem to report, not to raise
        problems.append(f"{path.name} does not load: {type(err).__name__}: {err}")
        return
    if not scene.graph.nodes_geometry:
        problems.append(f"{path.name} has no geometry")


def _check_scene_json(path: Path, names: list[str] | None, problems: list[str]) -> list[str] | None:
    try:
        data = json.loads(path.read_text())
        # scene_builder.serialize wraps the scene: {"format", "version", "scene": {..., "objects"}}.
        # (Read as plain JSON here: exporters do not import scene_builder.serialize.)
        if data.get("format") != "scene-builder/scene":
            raise ValueError(f"format is {data.get('format')!r}, not 'scene-builder/scene'")
        scene_names = sorted(o["asset"]["name"] for o in data["scene"]["objects"])
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as err:
        problems.append(f"{path.name} is not a readable scene: {err!r}")
        return names
    if names is not None and scene_names != names:
        problems.append(f"{path.name} objects {scene_names} differ from scene.xml objects {names}")
    return scene_names


def _check_report(path: Path, names: list[str] | None, problems: list[str]) -> None:
    try:
        report = json.loads(path.read_text())
    except (ValueError, RecursionError) as err:
        problems.append(f"{path.name} is not JSON: {err}")
        return
    if not isinstance(report, dict):
        problems.append(f"{path.name} is not a JSON object")
        return
    for key in ("timings_s", "objects", "layout"):
        if key not in report:
            problems.append(f"{path.name} has no '{key}'")
    layout = report.get("layout") if isinstance(report.get("layout"), dict) else {}
    for key in ("max_penetration_m", "settle_max_drift_m"):
        v = layout.get(key)
        if not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
            problems.append(f"{path.name}: layout.{key} is missing or not a non-negative number ({v!r})")
    timings = report.get("timings_s")
    if isinstance(timings, dict) and any(not isinstance(t, (int, float)) or t < 0 for t in timings.values()):
        problems.append(f"{path.name}: timings_s has negative or non-numeric entries")
    objects = report.get("objects")
    if isinstance(objects, list) and names is not None:
        # Objects that became static background are reported with a reason but are no scene bodies.
        rnames = sorted(str(o.get("name")) for o in objects if isinstance(o, dict) and not o.get("became_background"))
        if rnames != names:
            problems.append(f"{path.name} objects {rnames} differ from the scene's {names}")
