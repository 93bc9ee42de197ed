"""Exporters: MJCF (MjSpec), USD with UsdPhysics, URDF (per object; the scene as an option), SDF
(SDFormat 1.9), glTF binary, a rerun recording, and a checker of an output folder. Importing this package is cheap: every heavy library is imported
inside the function that uses it.

Each writer validates its own output with its consumer (MuJoCo, ``pxr.UsdValidation``,
MuJoCo's URDF importer, libsdformat when its checker is built, trimesh) and raises :class:`scene_builder.errors.ExportError` naming the
object the consumer rejects.
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

from scene_builder.config import ExportConfig
from scene_builder.model import ExportedFiles, Scene

if TYPE_CHECKING:  # pragma: no cover
    from scene_builder.model import Fidelity, LayoutResult, Perception, PhysicsVerdict

__all__ = [
    "check_output", "export_scene", "record_scene", "write_gltf", "write_mjcf", "write_object_urdfs", "write_sdf", "write_urdf",
    "write_usd",
]


def write_mjcf(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.xml`` (+ ``meshes/``); see :mod:`exporters.mjcf`."""
    from exporters.mjcf import write_mjcf as _write

    return _write(scene, Path(out_dir))


def write_usd(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.usda``; see :mod:`exporters.usd`."""
    from exporters.usd import write_usd as _write

    return _write(scene, Path(out_dir))


def write_urdf(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.urdf`` (+ ``meshes/``); see :mod:`exporters.urdf`."""
    from exporters.urdf import write_urdf as _write

    return _write(scene, Path(out_dir))


def write_object_urdfs(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/urdf/<object>.urdf`` per object (+ ``placements.json``); see :mod:`exporters.urdf`."""
    from exporters.urdf import write_object_urdfs as _write

    return _write(scene, Path(out_dir))


def write_sdf(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.sdf`` (SDFormat 1.9); see :mod:`exporters.sdf`."""
    from exporters.sdf import write_sdf as _write

    return _write(scene, Path(out_dir))


def write_gltf(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.glb``; see :mod:`exporters.gltf`."""
    from exporters.gltf import write_gltf as _write

    return _write(scene, Path(out_dir))


def export_scene(scene: Scene, out_dir: Path, config: ExportConfig) -> ExportedFiles:
    """Write the formats switched on in ``config`` into ``out_dir`` and validate each one.

    The rerun recording is not written here (it needs perception and layout results): the
    pipeline calls :func:`record_scene`.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    usd = write_usd(scene, out_dir) if config.usd else None
    if usd is not None and config.usdz:
        from exporters.usd import write_usdz

        write_usdz(usd)
    # The SDF is written and checked on a second thread while the others are written here: most
    # of its time is libsdformat's checker process (0.4 s), waited on with the interpreter free.
    # It starts after USD, so pxr's plugins load with no other thread running (two native
    # libraries initialising on two threads at once can deadlock on the loader's lock).
    with ThreadPoolExecutor(1, thread_name_prefix="sdf") as pool:
        sdf = pool.submit(write_sdf, scene, out_dir) if config.sdf else None
        files = ExportedFiles(
            mjcf=write_mjcf(scene, out_dir) if config.mjcf else None,
            usd=usd,
            urdf=write_urdf(scene, out_dir) if config.scene_urdf else None,
            gltf=write_gltf(scene, out_dir) if config.gltf else None,
            object_urdfs=write_object_urdfs(scene, out_dir) if config.urdf else None,
        )
        return dataclasses.replace(files, sdf=None if sdf is None else sdf.result())


def record_scene(
    out_path: Path,
    *,
    scene: Scene,
    perception: "Perception | None" = None,
    layout: "LayoutResult | None" = None,
    verdict: "PhysicsVerdict | None" = None,
    fidelity: "Fidelity | None" = None,
    spawn: bool = False,
) -> Path:
    """Save a rerun recording of the build to ``out_path`` (``.rrd``); see :mod:`exporters.rerun_viz`."""
    from exporters.rerun_viz import record_scene as _record

    return _record(Path(out_path), scene=scene, perception=perception, layout=layout, verdict=verdict,
                   fidelity=fidelity, spawn=spawn)


def check_output(out_dir: Path) -> tuple[str, ...]:
    """Problems found in an output folder (empty when it is fine); see :mod:`exporters.check`."""
    from exporters.check import check_output as _check

    return _check(Path(out_dir))
