"""Command line: ``scene-builder IMAGE`` (short for ``scene-builder build IMAGE``) and friends.

Every failure the user can act on is printed as one line ``error: ...`` with a non-zero exit
status; nothing half-written is left behind. Only argparse and the standard library are imported
at start-up, so ``--help`` is instant.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

COMMANDS = ("build", "batch", "demo", "bench", "check", "view", "models")

_DESCRIPTION = """\
Turn one photo of a room into a simulation-ready digital twin: every visible movable object as a
watertight, metric, physically parameterised asset textured with the photo, placed where it was
seen with nothing interpenetrating; everything else the camera saw as one static, photo-textured
background it rests on. Exported as MJCF (MuJoCo), USD with UsdPhysics (--usdz packs it), SDF
(SDFormat 1.9, for Gazebo), URDF (one file per object; --scene-urdf adds the scene as one URDF)
and glTF, with a rerun recording to inspect it.

  scene-builder room.jpg                      plain photo (depth estimated)
  scene-builder build room.jpg --depth d.png  RGB-D (uint16 PNG in millimetres)
  scene-builder batch photos/ -o scenes/      many photos, resumable (--workers N, --ray auto)
  scene-builder room.jpg --robot panda        ... with a Franka Panda on the floor, its arm reaching a surface
  scene-builder demo                          render a procedural room and rebuild it
  scene-builder check room_scene              re-validate an output folder
  scene-builder check room_scene --interact   ... and push its objects, open its doors in MuJoCo
  scene-builder view room_scene               open the rerun viewer on a saved scene

Frames: world Z up, metres, kilograms, floor at z = 0; camera frame OpenCV (x right, y down, z forward).

Output folder: -o replaces only a folder scene-builder wrote (its .scene-builder marker records
every file with its hash) and only if nothing in it was added or changed since; --overwrite
replaces such a folder even so. A folder scene-builder did not write is never replaced. The
current folder and a folder holding the input are always refused. Without -o the output is
./<image stem>_scene, which is replaced only by a build of the same image.

Exit status: 0 ok, 1 other failure, 2 usage error (bad command line), 3 input error (bad or
missing file, implausible depth or intrinsics, output folder refused), 4 model weights missing,
5 export failed, 130 interrupted; `check` exits 1 when it finds a problem (with --interact also a
push or an opening that failed). Errors are one line 'error: ...'; doubtful input the build goes
on with is one line 'warning: ...'.
"""


def _intrinsics(text: str) -> tuple[float, float, float, float]:
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected fx,fy,cx,cy in pixels, got {text!r}") from None
    if len(values) != 4:
        raise argparse.ArgumentTypeError(f"expected 4 numbers fx,fy,cx,cy, got {len(values)}")
    return values  # type: ignore[return-value]


def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (v > 0 and v != float("inf")):
        raise argparse.ArgumentTypeError(f"expected a positive finite number, got {text!r}")
    return v


def _fov(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a field of view in degrees, got {text!r}") from None
    if not 1.0 <= v <= 175.0:
        raise argparse.ArgumentTypeError(f"field of view must be between 1 and 175 degrees, got {text}")
    return v


def _add_build_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "-o",
        "--out",
        type=Path,
        help="output folder (default: ./<image stem>_scene, replaced only by a build of the same image)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the output folder scene-builder wrote even if files in it were added or changed since (they are "
        "deleted); a folder scene-builder did not write is never replaced",
    )
    _add_scene_options(p)


def _add_scene_options(p: argparse.ArgumentParser) -> None:
    """The options of a build shared by ``build`` and ``batch`` (all but the output folder)."""
    p.add_argument("--seed", type=int, default=0, help="random seed; the output is deterministic for a given input and seed (default 0)")
    p.add_argument(
        "--viz",
        choices=("save", "spawn", "off"),
        default="save",
        help="rerun recording: save OUT/scene.rrd (default), spawn = save and open the viewer, off = none",
    )
    p.add_argument("--models-dir", type=Path, help="folder with learned model weights (also $SCENE_BUILDER_MODELS)")
    p.add_argument(
        "--offline",
        action="store_true",
        help="never download weights (also HF_HUB_OFFLINE=1); by default the first run downloads Depth Anything V2, "
        "SAM 2 and Grounding DINO (about 945 MB) when the network allows, else says which fallback it uses",
    )
    p.add_argument("--depth-backend", default="auto", help="depth backend when no depth map is given (default auto; see `models list`)")
    p.add_argument(
        "--segmentation-backend",
        default="auto",
        help="instance segmentation backend: detections (offline detectors in the models dir), sam2, depth-clusters "
        "(default auto: the first available)",
    )
    p.add_argument("--settle-s", type=_positive, default=3.0, help="most seconds of simulation in the stability check (default 3; it stops sooner once everything is at rest)")
    p.add_argument("--adopt-settled", action="store_true", help="write the poses after the settle simulation instead of the solved ones")
    p.add_argument(
        "--robot",
        metavar="NAME",
        help="place a robot on a free floor spot facing a surface its arm reaches (MJCF and USD, prefix robot/): "
        "panda (Franka Panda), mobile_panda (Panda on a holonomic base), tidybot (Stanford TidyBot, Menagerie only)",
    )
    p.add_argument(
        "--robot-source",
        choices=("auto", "menagerie", "built-in"),
        default="auto",
        help="where the robot model comes from: auto = MuJoCo Menagerie (downloaded once into its cache), "
        "else the built-in model; --offline means built-in (default auto)",
    )
    p.add_argument("--no-usd", action="store_true", help="skip scene.usda")
    p.add_argument("--usdz", action="store_true", help="also package the USD stage and its textures as one scene.usdz file for hand-off")
    p.add_argument("--no-urdf", action="store_true", help="skip the per-object URDFs (OUT/urdf/<object>.urdf)")
    p.add_argument(
        "--scene-urdf",
        action="store_true",
        help="also write the whole scene as one URDF, OUT/scene.urdf (objects on floating joints to a world link, "
        "which many URDF tools reject)",
    )
    p.add_argument("--no-sdf", action="store_true", help="skip scene.sdf (SDFormat 1.9 world)")
    p.add_argument("--no-gltf", action="store_true", help="skip scene.glb")
    p.add_argument("-q", "--quiet", action="store_true", help="no per-stage lines")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage dump), consistent with every other failure."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"error: {message} (see '{self.prog} --help')\n")


def make_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="scene-builder", description=_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    b = sub.add_parser(
        "build",
        help="build a scene from one photo (the default command)",
        description="Build a simulation-ready scene from one photo.",
        epilog="Exit status: 0 ok, 2 usage error, 3 input error (bad file, implausible depth or intrinsics, output folder "
        "refused), 4 model weights missing, 5 export failed; see scene-builder --help.",
    )
    b.add_argument("image", type=Path, help="the photo (JPEG/PNG; EXIF orientation is applied)")
    b.add_argument("--depth", type=Path, help="aligned depth map: uint16 PNG in millimetres, float TIFF or .npy in metres; same size as the image")
    b.add_argument(
        "--depth-scale",
        type=_positive,
        metavar="M",
        help="metres per unit of the depth file (default: 0.001 for integer files, 1 for float files). Without it an "
        "8-bit depth image is refused, and so is depth whose median is no room's (0.4-15 m), with the scale that would fit",
    )
    cam = b.add_mutually_exclusive_group()
    cam.add_argument("--intrinsics", type=_intrinsics, metavar="FX,FY,CX,CY", help="pinhole intrinsics in pixels")
    cam.add_argument(
        "--fov-deg",
        type=_fov,
        metavar="F",
        help="horizontal field of view in degrees (1-175); wins over a camera.json beside the image and the EXIF focal length "
        "(a warning says so when they disagree); default: camera.json, else EXIF, else 60",
    )
    _add_build_options(b)

    _add_batch_parser(sub)

    d = sub.add_parser("demo", help="render a procedural room with MuJoCo, rebuild it, and compare with the truth")
    d.add_argument("-o", "--out", type=Path, default=Path("demo_scene"), help="output folder (default demo_scene/)")
    d.add_argument("--overwrite", action="store_true", help="replace the output folder scene-builder wrote even if it was changed since")
    d.add_argument("--seed", type=int, default=0, help="room and build seed (default 0)")
    d.add_argument("--objects", type=int, default=6, help="number of objects in the room (default 6)")
    d.add_argument("--viz", choices=("save", "spawn", "off"), default="save", help="rerun recording (default save)")

    be = sub.add_parser("bench", help="score the pipeline and a naive baseline against ground truth")
    be.add_argument("--suite", choices=("synthetic", "real", "novel-view"), default="synthetic",
                    help="procedural rooms, real RGB-D photos, or the twin seen from other cameras (real multi-view frames and "
                         "procedural rooms from orbit cameras, beside the photo-on-a-box and everything-background controls)")
    be.add_argument("--rooms", type=int, default=None, help="number of procedural rooms (default 20 for synthetic, 4 for novel-view)")
    be.add_argument("--data", type=Path, help="folder of samples: the ../shared/data/real format (real suite), the ../shared/data/multiview "
                                              "format (novel-view suite)")
    be.add_argument("--json", type=Path, default=Path("bench.json"), help="where to write the results (default bench.json)")
    be.add_argument("--seed", type=int, default=0, help="seed (default 0)")

    c = sub.add_parser("check", help="re-validate an output folder (MJCF compiles and is stable, USD validates, files resolve)")
    c.add_argument("out", type=Path, help="an output folder written by `scene-builder build`")
    c.add_argument("--interact", action="store_true",
                   help="also run the interaction probes in MuJoCo: push every movable object 6 cm with a pusher of at most "
                        "100 N that collides with everything (it must move 2-10 cm without toppling, every other object less "
                        "than 1 cm; a push blocked, too heavy or without room for the pusher fails with its reason) and pull "
                        "every door and drawer open (at least half its range, within its limits, the carcass still); writes "
                        "OUT/interaction.json; exit status 1 when any probe fails")

    v = sub.add_parser("view", help="open the rerun viewer on OUT/scene.rrd (or write its view to a PNG without a display)")
    v.add_argument("out", type=Path, help="an output folder (or a .rrd file)")
    vm = v.add_mutually_exclusive_group()
    vm.add_argument("--screenshot", type=Path, metavar="PNG",
                    help="write the default view (photo beside the twin rendered from the photo's camera, 3D view, report) to PNG headless, instead of opening the viewer")
    vm.add_argument("--orbit", type=Path, metavar="PNG",
                    help="write a sheet of the twin rendered with MuJoCo (OUT/scene.xml): the photo, the photo's camera, orbits of "
                         "-30 and +30 degrees about the objects, a view from above; below, the same views of the objects alone "
                         "(PNG, or JPEG by the suffix)")

    m = sub.add_parser("models", help="list or fetch learned model weights")
    msub = m.add_subparsers(dest="models_command", metavar="ACTION", required=True)
    ml = msub.add_parser("list", help="show each known model and whether its weights are available locally")
    ml.add_argument("--models-dir", type=Path, help="folder with model weights (also $SCENE_BUILDER_MODELS)")
    mf = msub.add_parser("fetch", help="download model weights (needs a network; HF_ENDPOINT selects a mirror)")
    mf.add_argument("names", nargs="*", help="model names (default: the ones a build uses, Depth Anything V2, SAM 2 and Grounding DINO, about 945 MB)")
    mf.add_argument("--models-dir", type=Path, help="where to put them (default: the Hugging Face cache)")
    return parser


def _non_negative_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected 0 or more, got {v}")
    return v


def _positive_int(text: str) -> int:
    v = _non_negative_int(text)
    if v == 0:
        raise argparse.ArgumentTypeError("expected 1 or more, got 0")
    return v


def _add_batch_parser(sub) -> None:
    ba = sub.add_parser(
        "batch",
        help="build many photos into OUT_ROOT/<name>/, resumable, on local worker processes or a Ray cluster",
        description="Build every photo of INPUT into OUT_ROOT/<name>/ exactly as `build` would. INPUT is a folder (searched "
        "recursively) or a text file listing photos or sample folders, one a line. A photo's depth.png and camera.json in "
        "its folder are used (the ../shared/data layout: rgb.jpg|png, depth.png in millimetres, camera.json); <name> is the "
        "photo's path relative to INPUT with / written __ (a sample folder's rgb.* is named after the folder). "
        "OUT_ROOT/manifest.sqlite records each item's state, attempts, timings, error and scene-builder version: a rerun "
        "skips done items, resumes a killed run (an unfinished item is rebuilt, never built twice) and retries failed items "
        "with --retry-failed. One bad photo fails alone.",
        epilog="Exit status: 0 every item done, 1 some item failed (listed, and in the manifest), 2 usage error, 3 input error "
        "(INPUT missing, OUT_ROOT inside INPUT or not a batch's, another batch running on OUT_ROOT).",
    )
    ba.add_argument("input", type=Path, metavar="INPUT_DIR_OR_LIST", help="folder of photos / sample folders, or a text file listing them")
    ba.add_argument("-o", "--out", type=Path, required=True, metavar="OUT_ROOT", help="output root: one folder per photo and manifest.sqlite")
    ba.add_argument("--workers", type=_positive_int, metavar="N", help="worker processes (default 1; with --ray: at most N tasks at once, default every CPU of the cluster)")
    ba.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run the items as Ray tasks: auto (the running cluster, `ray start`), local (start one here) or a cluster "
        "address; every node needs scene-builder and the same paths (pip install 'scene-builder[ray]')",
    )
    ba.add_argument("--retry-failed", action="store_true", help="build again the items that failed in an earlier run")
    ba.add_argument("--since-version", metavar="VERSION", help="rebuild done items made by a scene-builder older than VERSION")
    ba.add_argument("--retries", type=_non_negative_int, default=1, metavar="N",
                    help="extra attempts, in the same run, of an item whose worker died or went over the memory limit (default 1)")
    ba.add_argument("--max-worker-memory-gb", type=_positive, default=8.0, metavar="GB",
                    help="resident memory limit of one worker: a worker over it is killed and replaced, its item failed and retried (default 8)")
    ba.add_argument("--max-items-per-worker", type=_positive_int, metavar="N", help="replace a worker after N photos (default never)")
    ba.add_argument("--overwrite", action="store_true", help="replace OUT_ROOT/<name> scene-builder wrote even if it was changed since")
    _add_scene_options(ba)


def _version() -> str:
    from scene_builder import __version__

    return __version__


def _normalise_argv(argv: list[str]) -> list[str]:
    """``scene-builder IMAGE ...`` is short for ``scene-builder build IMAGE ...``."""
    if argv and not argv[0].startswith("-") and argv[0] not in COMMANDS:
        return ["build", *argv]
    return argv


def _build_config(args: argparse.Namespace):
    """The BuildConfig of the scene options (:func:`_add_scene_options`)."""
    from dataclasses import replace

    from scene_builder.config import BuildConfig, ExportConfig, LayoutConfig, PerceptionConfig, RobotConfig

    return BuildConfig(
        seed=args.seed,
        perception=replace(
            PerceptionConfig(),
            models_dir=args.models_dir,
            depth_backend=args.depth_backend,
            segmentation_backend=args.segmentation_backend,
        ),
        layout=replace(LayoutConfig(), settle_s=args.settle_s, adopt_settled=args.adopt_settled),
        export=ExportConfig(usd=not args.no_usd, usdz=args.usdz and not args.no_usd, urdf=not args.no_urdf,
                            scene_urdf=args.scene_urdf, sdf=not args.no_sdf, gltf=not args.no_gltf, viz=args.viz),
        robot=RobotConfig(args.robot, args.robot_source, args.offline),
    )


def _cmd_build(args: argparse.Namespace) -> int:
    from scene_builder.config import InputSpec
    from scene_builder.pipeline import build, default_out_dir

    inputs = InputSpec(args.image, args.depth, args.depth_scale, args.intrinsics, args.fov_deg)
    config = _build_config(args)
    out = args.out or default_out_dir(args.image)
    if args.robot:  # a mistyped robot is said before any download or stage
        from generation.robot import check_robot_request

        check_robot_request(args.robot, args.robot_source, args.offline)
    if args.image.is_file():  # no download before a missing photo is reported (by build, below)
        _prepare_weights(config.perception, need_depth=args.depth is None, offline=args.offline, quiet=args.quiet)
    result = build(inputs, out, config, progress=not args.quiet, overwrite=args.overwrite, default_name=args.out is None)
    _print_summary(result)
    return 0


def _cmd_batch(args: argparse.Namespace) -> int:
    from scene_builder.batch import BatchOptions, run_batch

    config = _build_config(args)
    if args.input.exists():
        _prepare_weights(config.perception, need_depth=True, offline=args.offline, quiet=args.quiet)
    options = BatchOptions(
        workers=args.workers or 1 if args.ray is None else args.workers,
        ray=args.ray,
        retry_failed=args.retry_failed,
        since_version=args.since_version,
        retries=args.retries,
        max_worker_memory_gb=args.max_worker_memory_gb,
        max_items_per_worker=args.max_items_per_worker,
        overwrite=args.overwrite,
        progress=not args.quiet,
    )
    summary = run_batch(args.input, args.out, config, options)
    print(summary.manifest)
    if summary.failed_total:
        name, error = summary.errors[0]
        print(f"error: {summary.failed_total} of {summary.total} items failed (first: {name}: {_one_line(error)}); see {summary.manifest}", file=sys.stderr)
        return 1
    return 0


def _prepare_weights(perception_config, need_depth: bool, offline: bool, quiet: bool) -> None:
    """Download the default learned models on the first networked run (progress bars on stderr),
    or say in one line which fallback the build uses and why."""
    from perception.backends import prepare_learned_weights

    for line in prepare_learned_weights(perception_config, need_depth=need_depth, offline=offline, progress=not quiet):
        if not quiet:
            print(line, file=sys.stderr)


def _print_summary(result) -> None:
    from rich.markup import escape

    from scene_builder.pipeline import stderr_console

    from scene_builder.report import fates_line

    v = result.verdict
    console = stderr_console()
    console.print(
        f"[bold]{escape(fates_line(result.fates))}[/bold] -> {escape(str(result.out_dir))}/  "
        f"(max penetration {v.max_penetration_m * 1000:.2f} mm, settle drift {v.settle_max_drift_m * 1000:.1f} mm, "
        f"{'stable' if v.stable else 'NOT stable'})"
    )
    print(result.out_dir)


def _cmd_demo(args: argparse.Namespace) -> int:
    import json
    import tempfile

    from scene_builder.config import BuildConfig, ExportConfig, InputSpec
    from scene_builder.bench.render import write_demo_input
    from scene_builder.bench.truth import compare_to_ground_truth
    from scene_builder.outdir import add_to_marker
    from scene_builder.pipeline import build, stderr_console

    with tempfile.TemporaryDirectory(prefix="scene-builder-demo-") as tmp:
        sample = write_demo_input(Path(tmp) / "room", seed=args.seed, n_objects=args.objects)
        cam = json.loads((sample / "camera.json").read_text())
        inputs = InputSpec(sample / "rgb.png", sample / "depth.png", 0.001, (cam["fx"], cam["fy"], cam["cx"], cam["cy"]))
        result = build(
            inputs, args.out, BuildConfig(seed=args.seed, export=ExportConfig(viz=args.viz)), progress=True, overwrite=args.overwrite
        )
        comparison = compare_to_ground_truth(result.scene, sample)
    (args.out / "ground_truth_comparison.json").write_text(json.dumps(comparison, indent=2) + "\n")
    add_to_marker(args.out, "ground_truth_comparison.json")
    _print_summary(result)
    stderr_console().print(
        "fidelity vs the rendered room: "
        + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in comparison["summary"].items())
    )
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    if args.suite == "novel-view":
        import json

        from scene_builder.bench.novel_view import DEFAULT_MULTIVIEW, markdown, run
        from scene_builder.pipeline import stderr_console

        rooms = 4 if args.rooms is None else args.rooms
        doc = run(rooms=rooms, seed=args.seed, data_dir=args.data or DEFAULT_MULTIVIEW, console=stderr_console())
        doc["command"] = f"scene-builder bench --suite novel-view --rooms {rooms} --seed {args.seed}" + (f" --data {args.data}" if args.data else "") + f" --json {args.json}"
        args.json.write_text(json.dumps(doc, indent=1, default=str) + "\n")
        print(markdown(doc))
        return 0
    from scene_builder.bench.suites import run_bench

    run_bench(args.suite, 20 if args.rooms is None else args.rooms, args.data, args.json, seed=args.seed)
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from exporters import check_output

    from scene_builder.errors import InputError

    if not args.out.is_dir():
        raise InputError(f"{args.out} is not an output folder; pass the folder written by `scene-builder build`")
    if args.interact:
        _check_interaction_writable(args.out)  # before anything runs: --interact writes into the folder
    problems = check_output(args.out)
    if args.interact:
        problems = problems + _interact(args.out)
    for p in problems:
        print(f"FAIL {p}", file=sys.stderr)
    if problems:
        print(f"error: {args.out}: {len(problems)} problem(s) found", file=sys.stderr)
        return 1
    print(f"ok: {args.out} passes every check")
    return 0


def _check_interaction_writable(out: Path) -> None:
    """Raise InputError unless ``out`` is a build of scene-builder whose interaction.json is
    absent or the one scene-builder wrote (so writing it destroys nothing of the user's)."""
    from scene_builder.errors import InputError
    from scene_builder.outdir import MARKER, owns_file, read_marker

    if read_marker(out) is None:
        raise InputError(
            f"{out} is not an output folder of scene-builder (no {MARKER} beside report.json), and --interact writes "
            "interaction.json into it; run `scene-builder check` without --interact, or pass a build's folder"
        )
    if not owns_file(out, "interaction.json"):
        raise InputError(
            f"{out / 'interaction.json'} was not written by scene-builder or was changed since; move it away, then run --interact again"
        )


def _interact(out: Path) -> tuple[str, ...]:
    """Run the interaction probes on OUT/scene.xml, print one line per probe, write
    OUT/interaction.json (``out`` checked by :func:`_check_interaction_writable`); returns the
    probes that miss the bar."""
    import dataclasses
    import json

    from layout.interaction import fixed_objects, interaction_problems, joint_summary, load_probe_model, probe_lines, probe_scene, push_failures
    from scene_builder.outdir import add_to_marker, replace_file

    plans, pushes, joints = probe_scene(out / "scene.xml")
    fixed = fixed_objects(load_probe_model(out / "scene.xml"))
    for line in probe_lines(plans, pushes, joints, fixed):
        print(line)
    problems = interaction_problems(pushes, joints)
    failures = {r.name: list(push_failures(r)) for r in pushes}
    doc = {
        "push_summary": {"movable": len(pushes), "succeeded": sum(not f for f in failures.values()),
                         "failed": sum(bool(f) for f in failures.values())},
        "push_plans": [dataclasses.asdict(p) for p in plans],
        "pushes": [{**dataclasses.asdict(r), "ok": not failures[r.name], "failures": failures[r.name]} for r in pushes],
        "joints": [{f.name: getattr(j, f.name) for f in dataclasses.fields(j) if f.name not in ("times_s", "positions")} for j in joints],
        "joint_summary": joint_summary(joints, fixed),
        "problems": list(problems),
    }
    _check_interaction_writable(out)  # again: the probes took a while
    replace_file(out, "interaction.json", json.dumps(_finite(doc), indent=2, allow_nan=False) + "\n")
    add_to_marker(out, "interaction.json")
    return problems


def _finite(v):
    """``v`` with every NaN or infinite float replaced by None (JSON has no NaN)."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    return v


def _cmd_view(args: argparse.Namespace) -> int:
    import subprocess

    from scene_builder.errors import InputError

    if args.orbit is not None:
        from exporters.orbit import orbit_sheet

        print(orbit_sheet(args.out, args.orbit))
        return 0
    rrd = args.out if args.out.suffix == ".rrd" else args.out / "scene.rrd"
    if not rrd.is_file():
        raise InputError(f"no recording at {rrd}; build with --viz save (the default) first")
    if args.screenshot is not None:
        from exporters.rerun_viz import screenshot

        print(screenshot(rrd, args.screenshot))
        return 0
    return subprocess.call([sys.executable, "-m", "rerun", str(rrd)])


def _cmd_models(args: argparse.Namespace) -> int:
    from perception.models import MODELS, fetch_models, list_models

    if args.models_command == "list":
        for s in list_models(args.models_dir):
            where = s.location if s.available else s.reason
            print(f"{'✓' if s.available else '✗'} {s.name:<28} {s.task:<13} {s.license:<14} {s.repo_id}  {where}")
        return 0
    names = tuple(args.names) or tuple(m.name for m in MODELS if m.default and m.source == "huggingface")
    for path in fetch_models(names, args.models_dir):
        print(path)
    return 0


#: The cyclic garbage collector's first threshold for a run of the command (CPython's default:
#: 700 allocations). A build allocates millions of small objects and makes few cycles: at the
#: default, 000003's build spent 0.33 s in 760 collections, at 10 000 0.13 s in 47, with the same
#: peak memory (BENCHMARKS.md, cold start, 2026-11-29 seventh session).
GC_THRESHOLD = 10_000


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("MUJOCO_GL", "egl")
    import gc

    gc.set_threshold(GC_THRESHOLD, *gc.get_threshold()[1:])
    parser = make_parser()
    args = parser.parse_args(_normalise_argv(list(sys.argv[1:] if argv is None else argv)))
    if args.command is None:
        parser.print_help()
        return 2
    from scene_builder.errors import SceneBuilderError

    handlers = {
        "build": _cmd_build,
        "batch": _cmd_batch,
        "demo": _cmd_demo,
        "bench": _cmd_bench,
        "check": _cmd_check,
        "view": _cmd_view,
        "models": _cmd_models,
    }
    try:
        with _one_line_warnings():
            return handlers[args.command](args)
    except SceneBuilderError as err:
        print(f"error: {_one_line(str(err))}", file=sys.stderr)
        return err.exit_code
    except OSError as err:  # the machine's, not the input's: disk full, permissions changed mid-build
        print(f"error: {_one_line(str(err))} (a file could not be read or written)", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


def _one_line(text: str) -> str:
    return " ".join(text.split())


class _one_line_warnings:
    """Print every InputWarning as one line ``warning: ...`` (other warnings as usual)."""

    def __enter__(self):
        import warnings

        from scene_builder.errors import InputWarning

        self._catch = warnings.catch_warnings()
        self._catch.__enter__()
        warnings.simplefilter("always", InputWarning)
        saved = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, InputWarning):
                print(f"warning: {_one_line(str(message))}", file=sys.stderr)
            else:
                saved(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        return self

    def __exit__(self, *exc):
        self._catch.__exit__(*exc)
        return False

if __name__ == "__main__":
    sys.exit(main())
