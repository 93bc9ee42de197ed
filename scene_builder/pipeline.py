"""The whole path from a photo to a simulation-ready scene, as a table of contents.

    perceive        photo (+ depth) -> observation, gravity-aligned camera, room, objects
    generate_assets each object -> simulation-ready asset and its observed pose
    solve_layout    assets -> penetration-free, supported placement in the world, as seen
    write_mjcf      scene -> OUT/scene.xml (MuJoCo)
    verify_scene    MuJoCo: penetration over all pairs, settle drift, render-and-compare
    make_background objects that do not stay at rest -> static background (then verify again)
    export_scene    scene -> OUT/scene.usda, scene.urdf, scene.glb
    record_scene    everything -> OUT/scene.rrd (rerun)
    write_report    OUT/scene.json, OUT/report.json

Everything is written into a hidden staging folder beside OUT and renamed into place at the end,
so a failed build leaves nothing half-written behind.
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from scene_builder.config import BuildConfig, InputSpec
from scene_builder.errors import InputError
from scene_builder.model import ExportedFiles, Fidelity, LayoutResult, Perception, PhysicsVerdict, Scene


#: Rounds of turning objects that do not stay at rest into static background (what rested on
#: them may in turn move).
UNSTABLE_ROUNDS = 2


@dataclass(frozen=True)
class BuildResult:
    """What a build produced. timings_s: (stage, seconds) in order, the last entry is ("total", s)."""

    perception: Perception
    layout: LayoutResult
    scene: Scene
    verdict: PhysicsVerdict
    fidelity: Fidelity | None
    files: ExportedFiles
    timings_s: tuple[tuple[str, float], ...]
    out_dir: Path
    report_path: Path


class StageLog:
    """Times each stage and prints one line per stage (and a progress bar for per-object loops)."""

    def __init__(self, show: bool) -> None:
        self.show = show
        self.timings: list[tuple[str, float]] = []
        self._console = None
        if show:
            from rich.console import Console

            self._console = Console(stderr=True, highlight=False)

    @contextmanager
    def stage(self, name: str, detail: Callable[[], str] | None = None) -> Iterator[None]:
        start = time.perf_counter()
        yield
        seconds = time.perf_counter() - start
        self.timings.append((name, seconds))
        if self._console is not None:
            extra = f"  [dim]{detail()}[/dim]" if detail else ""
            self._console.print(f"[green]✓[/green] {name:<14} {seconds:7.2f} s{extra}")

    @contextmanager
    def live(self, name: str, detail: Callable[[], str] | None = None) -> Iterator[Callable[[str], None]]:
        """A stage with no known length (perception, the physics check): a spinner, the stage's
        current step and the elapsed time stay on screen while it runs (rich, transient); yields a
        step(text) callback that replaces the step shown. The stage's line is printed as usual."""
        if self._console is None:
            with self.stage(name, detail):
                yield lambda _text: None
            return
        from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        with self.stage(name, detail):
            with Progress(
                SpinnerColumn(),
                TextColumn(f"{name:<14}"),
                TimeElapsedColumn(),
                TextColumn("[dim]{task.description}"),
                console=self._console,
                transient=True,
            ) as bar:
                task = bar.add_task("", total=None)
                yield lambda text: bar.update(task, description=text)

    @contextmanager
    def loop(self, name: str, total: int) -> Iterator[Callable[[str], None]]:
        """A stage that loops over objects: yields a tick(name) callback that advances a bar."""
        if self._console is None or total == 0:
            with self.stage(name):
                yield lambda _name: None
            return
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        with self.stage(name, lambda: f"{total} objects"):
            with Progress(
                TextColumn(f"  {name}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.description}"),
                TimeElapsedColumn(),
                console=self._console,
                transient=True,
            ) as bar:
                task = bar.add_task("", total=total)
                yield lambda obj_name: bar.update(task, advance=1, description=obj_name)


def default_out_dir(image_path: Path) -> Path:
    """``<image stem>_scene/`` beside the current directory."""
    return Path(f"{Path(image_path).stem}_scene")


def build(inputs: InputSpec, out_dir: Path, config: BuildConfig = BuildConfig(), progress: bool = False) -> BuildResult:
    """Run the whole pipeline on one photo and write every output into ``out_dir``.

    Raises scene_builder.errors.SceneBuilderError subclasses with a one-line message on bad input
    or a failed export; in that case ``out_dir`` is left as it was.
    """
    # Stages are imported here, not at module level, so `scene-builder --help` stays instant.
    from exporters import export_scene, record_scene, write_mjcf
    from generation import generate_assets
    from layout import make_background, settled_scene, solve_layout, unstable_objects, verify_scene
    from perception import perceive
    from scene_builder.report import build_report, write_report

    out_dir = Path(out_dir)
    _check_out_dir(out_dir)
    log = StageLog(progress)
    total_start = time.perf_counter()
    staging = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=out_dir.parent))
    try:
        with log.live("perception", lambda: _perception_summary(perceived)) as step:
            perceived = perceive(inputs, config.perception, config.seed, on_step=step)
        with log.loop("generation", len(perceived.objects)) as tick:
            generated = generate_assets(perceived, config.generation, config.seed, on_object=tick)
        with log.stage("layout", lambda: f"{len(layout.support)} support edges, {layout.iterations} iterations"):
            layout = solve_layout(perceived, generated, config.layout, config.seed)
        scene = layout.scene
        with log.stage("export mjcf"):
            mjcf_path = write_mjcf(scene, staging)
        with log.live("physics check", lambda: _verdict_summary(verdict)) as step:
            step(f"{config.layout.settle_s:g} s of simulation, then render-and-compare")
            verdict, fidelity = verify_scene(mjcf_path, scene, config.layout, perceived)
        for _ in range(UNSTABLE_ROUNDS):
            # An object that does not stay at rest where it was seen (a thin frame toppling off
            # a shelf) cannot stand there physically: it becomes static background, not moved.
            unstable = unstable_objects(verdict, scene, config.layout)
            if not unstable:
                break
            with log.stage("unstable to background", lambda: f"{len(unstable)} objects; {_verdict_summary(verdict)}"):
                layout = make_background(layout, unstable)
                scene = layout.scene
                shutil.rmtree(staging / "meshes", ignore_errors=True)  # the old objects' meshes
                mjcf_path = write_mjcf(scene, staging)
                verdict, fidelity = verify_scene(mjcf_path, scene, config.layout, perceived)
        if config.layout.adopt_settled:
            with log.live("adopt settled", lambda: _verdict_summary(verdict)) as step:
                step("re-checking the settled poses")
                scene = settled_scene(scene, verdict)
                mjcf_path = write_mjcf(scene, staging)
                verdict, fidelity = verify_scene(mjcf_path, scene, config.layout, perceived)
        with log.stage("export", lambda: ", ".join(p.name for p in _paths(files))):
            files = export_scene(scene, staging, dataclasses.replace(config.export, mjcf=False, viz="off"))
            files = dataclasses.replace(files, mjcf=mjcf_path)
        if config.export.viz != "off":
            with log.stage("rerun"):
                rrd = record_scene(
                    staging / "scene.rrd",
                    scene=scene,
                    perception=perceived,
                    layout=layout,
                    verdict=verdict,
                    fidelity=fidelity,
                    spawn=config.export.viz == "spawn",
                )
            files = dataclasses.replace(files, rerun=rrd)
        log.timings.append(("total", time.perf_counter() - total_start))
        report = build_report(inputs, config, perceived, layout, scene, verdict, fidelity, tuple(log.timings))
        write_report(staging, scene, report)
        _move_into_place(staging, out_dir)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    files = ExportedFiles(*[None if p is None else out_dir / p.name for p in dataclasses.astuple(files)])
    return BuildResult(perceived, layout, scene, verdict, fidelity, files, tuple(log.timings), out_dir, out_dir / "report.json")


def _paths(files: ExportedFiles) -> list[Path]:
    return [p for p in dataclasses.astuple(files) if p is not None]


def _perception_summary(p: Perception) -> str:
    backends = ", ".join(f"{b.task}: {b.backend}" for b in p.backends)
    return f"{len(p.objects)} objects, {len(p.room.walls)} walls; {backends}"


def _verdict_summary(v: PhysicsVerdict) -> str:
    return (
        f"max penetration {v.max_penetration_m * 1000:.2f} mm, drift {v.settle_max_drift_m * 1000:.1f} mm "
        f"over {v.simulated_s:g} s, {'stable' if v.stable else 'NOT stable'}"
    )


def _check_out_dir(out_dir: Path) -> None:
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"output path {out_dir} is a file; pass -o with a folder name")
    if not out_dir.parent.exists():
        raise InputError(f"output folder's parent {out_dir.parent} does not exist; create it or choose another -o")


def _move_into_place(staging: Path, out_dir: Path) -> None:
    """Replace ``out_dir`` with ``staging`` (renames on the same filesystem; the old output is
    removed only after the new one is in place)."""
    old = None
    if out_dir.exists():
        old = out_dir.with_name(f".{out_dir.name}.old-{staging.name.rsplit('-', 1)[-1]}")
        out_dir.rename(old)
    staging.rename(out_dir)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
