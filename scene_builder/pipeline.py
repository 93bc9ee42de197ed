"""The whole path from a photo to a simulation-ready scene, as a table of contents.

    perceive        photo (+ depth) -> observation, gravity-aligned camera, room, objects
    generate_assets each object -> simulation-ready asset and its observed pose
    solve_layout    assets -> penetration-free, supported placement in the world, as seen
    write_mjcf      scene -> OUT/scene.xml (MuJoCo)
    verify_scene    MuJoCo: penetration over all pairs, settle drift, render-and-compare
    make_background objects that do not stay at rest -> static background (then verify again)
    export_scene    scene -> OUT/scene.usda, urdf/ (+ scene.urdf), scene.sdf, scene.glb
    record_scene    everything -> OUT/scene.rrd (rerun)
    write_report    OUT/scene.json, OUT/report.json

Everything is written into a hidden staging folder beside OUT and renamed into place at the end,
so a failed build leaves nothing half-written behind.

Output safety (:mod:`scene_builder.outdir`): OUT replaces only a folder that scene-builder wrote
(its marker :data:`MARKER` records every file with its hash), and only when nothing in it was
added or changed since, unless ``overwrite`` is set; a folder scene-builder did not write is never
replaced. The current folder, a folder holding the input and a folder inside the input's folder
(unless that is the current folder) are always refused. The folder gets the permissions the
umask allows, like any folder the user makes.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from scene_builder.config import BuildConfig, InputSpec
from scene_builder.errors import InputError
from scene_builder.model import ExportedFiles, Fidelity, LayoutResult, Perception, PhysicsVerdict, Scene
from scene_builder.outdir import (  # noqa: F401 - MARKER, read_marker, add_to_marker: re-exported for callers of the pipeline
    MARKER,
    add_to_marker,
    check_location,
    check_out_dir,
    check_replaceable,
    make_staging,
    move_into_place,
    read_marker,
    real_out_dir,
    write_marker,
)


#: Rounds of turning objects that do not stay at rest into static background (what rested on
#: them may in turn move).
UNSTABLE_ROUNDS = 3
#: An object is re-seated where it came to rest at most this many times (re-seating one object
#: can leave its neighbour a millimetre inside it for the next round).
RESEAT_TIMES = 2


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
    first_verdict: PhysicsVerdict | None = None  # the physics check before any object became background

    @property
    def fates(self) -> dict:
        """What became of every perceived object (``scene_builder.report.object_fates``)."""
        from scene_builder.report import object_fates

        return object_fates(self.perception, self.layout, self.scene, self.first_verdict, self.verdict)


def stderr_console():
    """The rich console of the CLI's messages: on a terminal it wraps at the terminal's width;
    without one (a log file, CI) lines are never wrapped, so each message stays one line."""
    from rich.console import Console

    console = Console(stderr=True, highlight=False)
    if not console.is_terminal:
        console.soft_wrap = True
    return console


class StageLog:
    """Times each stage and prints one line per stage (and a progress bar for per-object loops)."""

    def __init__(self, show: bool) -> None:
        self.show = show
        self.timings: list[tuple[str, float]] = []
        self._console = stderr_console() if show else None

    @contextmanager
    def stage(self, name: str, detail: Callable[[], str] | None = None) -> Iterator[None]:
        start = time.perf_counter()
        yield
        seconds = time.perf_counter() - start
        self.timings.append((name, seconds))
        if self._console is not None:
            from rich.markup import escape

            extra = f"  [dim]{escape(detail())}[/dim]" if detail else ""
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
        from rich.markup import escape
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        with self.stage(name, lambda: f"{total} objects"):
            with Progress(
                TextColumn(f"  {name}", markup=False),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.description}"),
                TimeElapsedColumn(),
                console=self._console,
                transient=True,
            ) as bar:
                task = bar.add_task("", total=total)
                yield lambda obj_name: bar.update(task, advance=1, description=escape(obj_name))


def default_out_dir(image_path: Path) -> Path:
    """``<image stem>_scene/`` in the current folder. :func:`build` with ``default_name=True``
    replaces it only when it holds an earlier build of the same image (datasets call every frame
    ``rgb.jpg``: the build of another frame is refused, never silently replaced)."""
    return Path(f"{Path(image_path).stem}_scene")


def _final_check(scene, config: BuildConfig, last_round: bool):
    """Whether a physics check of ``scene`` is the build's last (its render-and-compare is then
    needed): the last settle round's, or one that finds nothing unstable; with
    ``adopt_settled`` the settled scene is checked once more after the rounds."""
    from layout import unstable_objects

    return lambda verdict: not config.layout.adopt_settled and (last_round or not unstable_objects(verdict, scene, config.layout))


def build(
    inputs: InputSpec,
    out_dir: Path,
    config: BuildConfig = BuildConfig(),
    progress: bool = False,
    overwrite: bool = False,
    default_name: bool = False,
) -> BuildResult:
    """Run the whole pipeline on one photo and write every output into ``out_dir``.

    ``out_dir`` is checked first (:func:`check_out_dir`): an existing folder is replaced only when
    scene-builder wrote it and nothing in it was added or changed since (with ``overwrite``: edited
    or not; a folder scene-builder did not write never); ``default_name`` says ``out_dir`` was not
    chosen by the user (then it is replaced only when it holds a build of the same image). A
    symbolic link is followed: the folder it points to is replaced, the link kept.

    Raises scene_builder.errors.SceneBuilderError subclasses with a one-line message on bad input
    or a failed export; in that case ``out_dir`` is left as it was.
    """
    # Stages are imported here, not at module level, so `scene-builder --help` stays instant.
    from exporters import export_scene, record_scene, write_mjcf
    from generation import generate_assets
    from layout import knocked, make_background, reseat_objects, reseatable, settled_scene, settled_together, solve_layout, unstable_objects, verify_scene
    from perception import perceive
    from perception.inputs import check_paths
    from scene_builder.report import build_report, write_report

    out_dir = Path(out_dir)
    check_paths(inputs)  # a missing photo is the first thing to say, before anything about the output
    check_out_dir(out_dir, inputs, overwrite=overwrite, default_name=default_name)
    if config.robot.name:
        from generation.robot import check_robot_request

        check_robot_request(config.robot.name, config.robot.source, config.robot.offline)
    log = StageLog(progress)
    total_start = time.perf_counter()
    dest = real_out_dir(out_dir)
    staging = make_staging(dest)
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
            verdict, fidelity = verify_scene(mjcf_path, scene, config.layout, perceived, fidelity_when=_final_check(scene, config, False))
        first_verdict = verdict  # before any object became background in the settle rounds
        reseated: dict[str, int] = {}  # how often each object was re-seated (at most RESEAT_TIMES)
        for round_ in range(UNSTABLE_ROUNDS):
            # An object that settled a little and came to rest is re-seated there (once); one
            # that does not stay at rest where it was seen (a thin frame toppling off a shelf)
            # cannot stand there physically: it becomes static background, not moved.
            unstable = unstable_objects(verdict, scene, config.layout)
            if not unstable:
                break
            last = round_ == UNSTABLE_ROUNDS - 1  # the last round re-seats nothing: it must end at rest
            reseat = {} if last else {n: r for n, r in reseatable(verdict, unstable, scene).items() if reseated.get(n, 0) < RESEAT_TIMES}
            give_up = {n: r for n, r in unstable.items() if n not in reseat}
            # What only fell because one of those fell onto it is checked again with that one held.
            held = set() if last else knocked(verdict, scene, set(give_up), set(give_up))
            give_up = {n: r for n, r in give_up.items() if n not in held}
            with log.stage("unstable repaired", lambda: f"{len(reseat)} re-seated, {len(give_up)} to background, {len(held)} checked again; {_verdict_summary(verdict)}"):
                if reseat:
                    # What came to rest against them moves with them (stable itself: within the
                    # drift bounds), so the group keeps the contacts it settled into.
                    together = settled_together(scene, verdict, set(reseat), set(give_up) | held)
                    with_them = {n: "moved with the objects re-seated beside it, where they came to rest together" for n in together}
                    layout = reseat_objects(layout, verdict, {**reseat, **with_them})
                    for n in reseat:
                        reseated[n] = reseated.get(n, 0) + 1
                if give_up:
                    layout = make_background(layout, give_up)
                scene = layout.scene
                shutil.rmtree(staging / "meshes", ignore_errors=True)  # the old objects' meshes
                mjcf_path = write_mjcf(scene, staging)
                verdict, fidelity = verify_scene(mjcf_path, scene, config.layout, perceived,
                                                 fidelity_when=_final_check(scene, config, round_ + 1 == UNSTABLE_ROUNDS))
        if config.layout.adopt_settled:
            with log.live("adopt settled", lambda: _verdict_summary(verdict)) as step:
                step("re-checking the settled poses")
                scene = settled_scene(scene, verdict)
                mjcf_path = write_mjcf(scene, staging)
                verdict, fidelity = verify_scene(mjcf_path, scene, config.layout, perceived)
        if config.robot.name:
            with log.stage("robot", lambda: _robot_summary(scene, verdict)):
                scene, mjcf_path, verdict = _add_robot(scene, staging, config)
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
        report = build_report(inputs, config, perceived, layout, scene, verdict, fidelity, tuple(log.timings), generated, first_verdict)
        write_report(staging, scene, report)
        shutil.rmtree(staging / ROBOT_WORK_DIR, ignore_errors=True)
        write_marker(staging, inputs)
        # Checked again: the build took a while, and someone may have put a file in out_dir. Its
        # contents are checked once it is set aside, so nothing added until then is lost.
        check_location(out_dir, inputs)
        move_into_place(
            staging, dest, verify=lambda old: check_replaceable(old, inputs, overwrite, default_name, shown=out_dir)
        )
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    finally:
        _release_mujoco_assets()
    files = ExportedFiles(*[None if p is None else out_dir / p.name for p in dataclasses.astuple(files)])
    return BuildResult(perceived, layout, scene, verdict, fidelity, files, tuple(log.timings), out_dir, out_dir / "report.json", first_verdict)


def _release_mujoco_assets() -> None:
    """Empty MuJoCo's process-wide asset cache. It keeps every decoded mesh and texture file it
    compiled, by path, up to 500 MB: a build's files were read from its staging folder, which is
    renamed or removed at the end, so its entries are never hit again, and a process building
    many photos (``scene-builder batch``) grew by about 80 MB per photo until the cap."""
    import mujoco

    mujoco.mj_clearCache(mujoco.mj_getCache())


#: Where the built-in robot's MJCF is written during a build (removed before the output is in place).
ROBOT_WORK_DIR = ".robot"


def _add_robot(scene: Scene, staging: Path, config: BuildConfig) -> tuple[Scene, Path, PhysicsVerdict]:
    """Load the robot and try its placements best first: keep the first whose geoms overlap
    nothing in the written MJCF and whose scripted reach gets to the target clear of the scene;
    then the physics check of the scene with the robot (its fidelity stays the twin's: the
    robot was not in the photo)."""
    from exporters import write_mjcf
    from generation.robot import load_robot
    from layout import verify_scene
    from layout.reach import PlacementTrials
    from layout.robot import alternatives, place_robot

    model = load_robot(config.robot.name, staging / ROBOT_WORK_DIR, config.robot.source, config.robot.offline)
    placements = place_robot(scene, model)
    # The scene is written and compiled once; each placement moves the robot in that model.
    mjcf_path = write_mjcf(dataclasses.replace(scene, robot=placements[0]), staging)
    chosen, why = PlacementTrials(mjcf_path, placements[0]).first_passing(placements, lambda p: alternatives(scene, p))
    if chosen is None:
        raise InputError(
            f"--robot {model.name}: no free spot found reaches its target clear of the scene ({'; '.join(why[:3])}); build without --robot"
        )
    with_robot = dataclasses.replace(scene, robot=chosen)
    if chosen is not placements[0]:
        mjcf_path = write_mjcf(with_robot, staging)
    verdict, _ = verify_scene(mjcf_path, with_robot, config.layout)
    return with_robot, mjcf_path, verdict


def _robot_summary(scene: Scene, verdict: PhysicsVerdict) -> str:
    r = scene.robot
    if r is None:
        return ""
    return (f"{r.model.name} ({r.model.source}) at ({r.position_m[0]:.2f}, {r.position_m[1]:.2f}) m facing {r.target_support}; "
            f"{_verdict_summary(verdict)}")


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


def load_stages(threads: int = 0) -> None:
    """Import every stage and the heavy libraries a build uses, once per process: what a batch
    worker loads before its first photo instead of during it. No torch: the offline build runs
    its models in onnxruntime and TFLite; a learned backend with hub weights imports torch when
    it is made. ``threads`` > 0 caps the intra-op threads of torch (``OMP_NUM_THREADS``, read
    when torch is imported, or now when it already is) for workers sharing a machine's cores."""
    import mujoco  # noqa: F401
    import pxr.Usd  # noqa: F401
    import rerun  # noqa: F401
    import trimesh  # noqa: F401

    import exporters  # noqa: F401
    import generation  # noqa: F401
    from generation.collision import import_coacd
    import layout  # noqa: F401
    import perception  # noqa: F401
    from perception.backends import build_registries  # noqa: F401

    import_coacd()  # onnxruntime first: the other order crashes at the first detection

    if threads > 0:
        os.environ.setdefault("OMP_NUM_THREADS", str(threads))
        if "torch" in sys.modules:
            sys.modules["torch"].set_num_threads(threads)
