"""Output safety and determinism on real builds (issue 12): a build replaces only its own output,
respects the umask, leaves the previous output intact when interrupted, and two builds of one
input give byte-identical scene.json, MJCF, USD, SDF, per-object URDFs, glTF and meshes; logs
without a terminal are not wrapped; a photo of 500 small objects builds in bounded time."""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from scene_builder.cli import main
from scene_builder.pipeline import MARKER

from .conftest import REPO

CLI = [sys.executable, "-m", "scene_builder.cli"]
DETERMINISTIC = ("scene.json", "scene.xml", "scene.usda", "scene.sdf", "scene.glb")


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> tuple[Path, list[str]]:
    """A small procedural RGB-D room (3 objects) and the build flags for it."""
    from scene_builder.bench.render import write_demo_input

    sample = write_demo_input(tmp_path_factory.mktemp("in") / "room", seed=1, n_objects=3)
    cam = json.loads((sample / "camera.json").read_text())
    flags = ["--depth", str(sample / "depth.png"), "--intrinsics", f"{cam['fx']},{cam['fy']},{cam['cx']},{cam['cy']}"]
    return sample / "rgb.png", flags


def _files(out: Path) -> dict[str, bytes]:
    names = [*DETERMINISTIC, *(f"{d}/{p.name}" for d in ("meshes", "urdf") for p in sorted((out / d).iterdir()))]
    return {n: (out / n).read_bytes() for n in names}


@pytest.fixture()
def work(tmp_path: Path, monkeypatch) -> Path:
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.slow
def test_rebuild_replaces_its_own_output_with_umask_permissions_and_follows_a_link(room, work: Path, capsys):
    image, flags = room
    out = work / "out"
    old_umask = os.umask(0o027)
    try:
        assert main([str(image), *flags, "-o", str(out), "-q", "--viz", "off"]) == 0
        assert (out.stat().st_mode & 0o777) == 0o750  # not mkdtemp's 0700
        assert ((out / "scene.xml").stat().st_mode & 0o777) == 0o640
        assert ((out / MARKER).stat().st_mode & 0o777) == 0o640
        assert ((out / "meshes").stat().st_mode & 0o777) == 0o750
        marker = json.loads((out / MARKER).read_text())
        assert marker["image"] == str(image.resolve()) and marker["version"] == 2
        assert set(marker["files"]) == {p.name for p in out.iterdir()} - {MARKER}
        written = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file() and p.name != MARKER)
        assert sorted(marker["hashes"]) == written and "meshes" in marker["folders"]
        digest = hashlib.sha256((out / "scene.xml").read_bytes()).hexdigest()
        assert marker["hashes"]["scene.xml"] == {"bytes": (out / "scene.xml").stat().st_size, "sha256": digest}
        first = _files(out)
        # a folder scene-builder wrote, unchanged, is replaced without --overwrite
        os.umask(0o022)
        assert main([str(image), *flags, "-o", str(out), "-q", "--viz", "off"]) == 0
        assert (out.stat().st_mode & 0o777) == 0o755
    finally:
        os.umask(old_umask)
    # Byte-identical rebuild in one process (across processes: test_two_processes_build_identical_bytes)
    assert _files(out) == first
    # -o a symbolic link to that build: the folder it points to is replaced, the link kept, and
    # nothing is left beside either (the set-aside folder was once a stray `.link.old-*` link)
    (work / "link").symlink_to(out)
    assert main([str(image), *flags, "-o", "link", "-q", "--viz", "off"]) == 0
    assert (work / "link").is_symlink() and (work / "link").resolve() == out and _files(out) == first
    assert sorted(p.name for p in work.iterdir()) == ["link", "out"]
    capsys.readouterr()


@pytest.mark.slow
def test_default_output_name_is_rebuilt_by_the_same_image(room, work: Path, capsys):
    image, flags = room
    assert main([str(image), *flags, "-q", "--viz", "off"]) == 0
    assert main([str(image), *flags, "-q", "--viz", "off"]) == 0
    assert (work / "rgb_scene" / "report.json").is_file()
    # another photo with the same stem must not silently replace it
    other = work / "elsewhere" / "rgb.png"
    other.parent.mkdir()
    other.write_bytes(image.read_bytes())
    capsys.readouterr()
    assert main([str(other), *flags, "-q", "--viz", "off"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "rgb_scene holds the build of another image" in err[0] and "-o elsewhere_rgb_scene" in err[0]


def _previous_output(out: Path, image: Path) -> dict[str, bytes]:
    """What an earlier build left in ``out``; returns its files' bytes."""
    from scene_builder.config import InputSpec
    from scene_builder.outdir import write_marker

    out.mkdir()
    (out / "report.json").write_text('{"objects": []}\n')
    (out / "scene.xml").write_text("<mujoco/>\n")
    write_marker(out, InputSpec(image))
    return {p.name: p.read_bytes() for p in out.iterdir()}


def test_interrupted_build_leaves_the_previous_output_intact(room, work: Path, monkeypatch, capsys):
    """Ctrl-C during perception: the previous output is untouched and the staging folder gone."""
    import perception

    image, flags = room
    out = work / "out"
    before = _previous_output(out, image)
    seen: list[str] = []

    def interrupted(*args, **kwargs):
        seen.extend(p.name for p in work.iterdir())
        raise KeyboardInterrupt

    monkeypatch.setattr(perception, "perceive", interrupted)
    assert main([str(image), *flags, "-o", str(out), "-q", "--viz", "off"]) == 130
    assert capsys.readouterr().err.strip() == "error: interrupted"
    assert any(name.startswith(".out.tmp-") for name in seen)  # the staging folder existed
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in work.iterdir()) == ["out"]


@pytest.mark.slow
def test_build_interrupted_after_writing_leaves_the_previous_output_intact(room, work: Path, monkeypatch, capsys):
    """Ctrl-C once the staging folder holds the MJCF: the same."""
    import exporters

    image, flags = room
    out = work / "out"
    before = _previous_output(out, image)
    staged: list[Path] = []
    real_write_mjcf = exporters.write_mjcf

    def write_then_interrupt(scene, folder):
        staged.append(real_write_mjcf(scene, folder))
        raise KeyboardInterrupt

    monkeypatch.setattr(exporters, "write_mjcf", write_then_interrupt)
    assert main([str(image), *flags, "-o", str(out), "-q", "--viz", "off"]) == 130
    assert capsys.readouterr().err.strip() == "error: interrupted"
    assert staged and staged[0].parent.name.startswith(".out.tmp-")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in work.iterdir()) == ["out"]


@pytest.mark.slow
def test_two_processes_build_identical_bytes_and_logs_are_not_wrapped(room, tmp_path: Path):
    """Two separate processes (different hash seeds) give the same bytes; the second writes to a
    folder with a long name, and its stderr (a pipe, not a terminal) keeps every line whole."""
    image, flags = room
    long_name = "a_folder_name_long_enough_that_an_80_column_console_would_have_wrapped_the_summary_line_" + "x" * 40
    outs = [tmp_path / "first", tmp_path / long_name]
    runs = []
    for seed, out in zip(("1", "2"), outs):
        env = {**os.environ, "PYTHONHASHSEED": seed, "COLUMNS": "80"}
        env.pop("CI", None)
        runs.append(subprocess.run([*CLI, str(image), *flags, "-o", str(out), "--viz", "off"], cwd=tmp_path, env=env,
                                   capture_output=True, text=True, timeout=600))
        assert runs[-1].returncode == 0, runs[-1].stderr[-2000:]
    a, b = (_files(o) for o in outs)
    assert sorted(a) == sorted(b)
    for name in a:
        assert a[name] == b[name], f"{name} differs between two builds of the same input"
    lines = runs[1].stderr.splitlines()
    assert any(re.search(rf"perceived: .* -> .*{long_name}/ +\(max penetration", line) for line in lines), lines[-3:]
    stage_lines = [line for line in lines if line.startswith("✓")]
    assert {line.split()[1] for line in stage_lines} >= {"perception", "generation", "layout", "export"}


# ------------------------------------------------------------------------------------------
# The output-folder rules, without a build
# ------------------------------------------------------------------------------------------


def test_output_folder_rules(work: Path):
    from scene_builder.config import InputSpec
    from scene_builder.errors import InputError
    from scene_builder.outdir import add_to_marker, check_out_dir, read_marker, write_marker

    photos = work / "photos"
    photos.mkdir()
    image = photos / "room.jpg"
    image.write_bytes(b"x")
    spec = InputSpec(image)
    check_out_dir(work / "new", spec)  # a new folder
    (work / "empty").mkdir()
    check_out_dir(work / "empty", spec)  # an empty folder holds nothing to lose
    with pytest.raises(InputError, match="inside the input's folder"):
        check_out_dir(photos / "room_scene", spec)
    os.chdir(photos)  # running in the photo's own folder: the default output lands there, allowed
    check_out_dir(Path("room_scene"), spec, default_name=True)
    with pytest.raises(InputError, match="current folder"):
        check_out_dir(Path("."), spec, overwrite=True)  # --overwrite never allows these
    os.chdir(work)
    with pytest.raises(InputError, match="holds the input"):
        check_out_dir(work / "photos", spec, overwrite=True)
    # a folder scene-builder wrote, then the demo's extra file recorded in its marker
    out = work / "out"
    out.mkdir()
    (out / "report.json").write_text("{}")
    write_marker(out, spec)
    assert read_marker(out)["files"] == ["report.json"]
    (out / "ground_truth_comparison.json").write_text("{}")
    with pytest.raises(InputError, match=r"added or changed since scene-builder wrote it \(added: ground_truth_comparison\.json\)"):
        check_out_dir(out, spec)
    add_to_marker(out, "ground_truth_comparison.json")
    check_out_dir(out, spec)
    (out / "report.json").unlink()  # a marker without report.json is not a build
    assert read_marker(out) is None


# ------------------------------------------------------------------------------------------
# Never lose work (issue 26): every refusal leaves every file of the user's as it was
# ------------------------------------------------------------------------------------------


def _snapshot(root: Path) -> dict[str, bytes | None]:
    """Every entry under ``root``: a file's bytes, None for a folder, the target for a link."""
    out: dict[str, bytes | None] = {}
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root).as_posix()
        out[rel] = os.readlink(p).encode() if p.is_symlink() else (None if p.is_dir() else p.read_bytes())
    return out


def _build_folder(out: Path, image: Path) -> None:
    """What a build writes, with a real marker (hashes of every file)."""
    from scene_builder.config import InputSpec
    from scene_builder.outdir import write_marker

    (out / "meshes").mkdir(parents=True)
    (out / "report.json").write_text('{"objects": []}\n')
    (out / "scene.xml").write_text('<mujoco><asset><mesh file="meshes/box.obj"/></asset></mujoco>\n')
    (out / "meshes" / "box.obj").write_text("v 0 0 0\n")
    write_marker(out, InputSpec(image))


@pytest.fixture()
def photo(work: Path) -> Path:
    path = work / "in" / "room.png"
    path.parent.mkdir()
    Image.fromarray(np.zeros((32, 32, 3), np.uint8)).save(path)
    return path


def _refused(argv: list[str], work: Path, capsys) -> str:
    """Run the CLI; it must exit 3 with one line and change nothing under ``work``."""
    before = _snapshot(work)
    capsys.readouterr()
    assert main(argv) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    assert _snapshot(work) == before
    return err[0]


def test_rebuild_refuses_a_file_added_deep_in_the_build_naming_it(photo: Path, work: Path, capsys):
    out = work / "out"
    _build_folder(out, photo)
    (out / "meshes" / "mine.obj").write_text("my own mesh")
    (out / "notes").mkdir()
    err = _refused([str(photo), "-o", "out", "-q"], work, capsys)
    assert "out holds files added or changed since scene-builder wrote it (added: meshes/mine.obj, notes)" in err
    assert "or pass --overwrite to replace the folder with them" in err


def test_rebuild_refuses_an_edited_file_naming_it(photo: Path, work: Path, capsys):
    out = work / "out"
    _build_folder(out, photo)
    text = (out / "scene.xml").read_text()
    (out / "scene.xml").write_text(text.replace("box.obj", "bax.obj"))  # same size, other bytes
    err = _refused([str(photo), "-o", "out", "-q"], work, capsys)
    assert "(changed: scene.xml)" in err


def test_overwrite_never_replaces_a_folder_scene_builder_did_not_write(photo: Path, work: Path, capsys):
    precious = work / "precious"
    (precious / "chapter1").mkdir(parents=True)
    (precious / "chapter1" / "thesis.tex").write_text("four years of work")
    (precious / "report.json").write_text("{}")  # a report.json alone does not make it a build
    err = _refused([str(photo), "-o", "precious", "--overwrite", "-q"], work, capsys)
    assert "precious exists and was not written by scene-builder (no .scene-builder beside report.json); " \
           "it is never replaced, even with --overwrite" in err
    # a marker that is not scene-builder's format does not make it one either
    (precious / MARKER).write_text('{"format": "something else", "files": []}')
    _refused([str(photo), "-o", "precious", "--overwrite", "-q"], work, capsys)


def test_an_older_marker_without_hashes_is_replaced_only_with_overwrite(photo: Path, work: Path, capsys):
    out = work / "out"
    out.mkdir()
    (out / "report.json").write_text("{}")
    (out / MARKER).write_text(json.dumps({"format": "scene-builder/output", "version": 1, "image": str(photo), "files": ["report.json"]}))
    err = _refused([str(photo), "-o", "out", "-q"], work, capsys)
    assert "written by an older scene-builder whose marker records no file hashes" in err and "pass --overwrite" in err
    from scene_builder.outdir import check_out_dir

    check_out_dir(out, overwrite=True)  # it is scene-builder's: --overwrite may replace it


def test_a_file_added_while_the_build_ran_is_kept(photo: Path, work: Path):
    """The contents are checked again once the old folder is set aside: a file added after the
    first check puts the old folder back, untouched, and the new build is not moved in."""
    from scene_builder.config import InputSpec
    from scene_builder.errors import InputError
    from scene_builder.outdir import check_out_dir, check_replaceable, make_staging, move_into_place, write_marker

    out = work / "out"
    _build_folder(out, photo)
    check_out_dir(out, InputSpec(photo))
    staging = make_staging(out)
    (staging / "report.json").write_text("{}")
    write_marker(staging, InputSpec(photo))
    (out / "meshes" / "late.obj").write_text("added during the build")
    before = _snapshot(out)
    with pytest.raises(InputError, match=r"added: meshes/late\.obj"):
        move_into_place(staging, out, verify=lambda old: check_replaceable(old, shown=out))
    assert _snapshot(out) == before
    assert sorted(p.name for p in work.iterdir()) == sorted(["in", "out", staging.name])  # the caller removes its staging


def test_a_link_as_output_replaces_the_folder_it_points_to_and_stays(photo: Path, work: Path):
    """What build() does at its end with -o LINK (the build itself: the slow test above): the
    folder behind the link is replaced, the link kept, nothing left beside them; a dangling link
    gets its folder made."""
    from scene_builder.config import InputSpec
    from scene_builder.outdir import check_out_dir, check_replaceable, make_staging, move_into_place, real_out_dir, write_marker

    out = work / "out"
    _build_folder(out, photo)
    (work / "link").symlink_to("out")
    (work / "dangling").symlink_to("later")
    for link in (work / "link", work / "dangling"):
        check_out_dir(link, InputSpec(photo))
        dest = real_out_dir(link)
        staging = make_staging(dest)
        (staging / "report.json").write_text('{"new": true}')
        write_marker(staging, InputSpec(photo))
        move_into_place(staging, dest, verify=lambda old: check_replaceable(old, shown=link))
        assert link.is_symlink() and json.loads((link / "report.json").read_text()) == {"new": True}
    assert sorted(p.name for p in work.iterdir()) == ["dangling", "in", "later", "link", "out"]
    assert os.readlink(work / "link") == "out" and os.readlink(work / "dangling") == "later"


def test_check_interact_writes_nothing_into_a_folder_that_is_not_a_build(photo: Path, work: Path, capsys):
    mine = work / "mine"
    mine.mkdir()
    (mine / "scene.xml").write_text("<mujoco/>\n")  # the user's own model
    (mine / "report.json").write_text("{}")
    before = _snapshot(work)
    assert main(["check", str(mine), "--interact"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mine is not an output folder of scene-builder" in err[0] and "without --interact" in err[0]
    assert _snapshot(work) == before
    # a build whose interaction.json is the user's (not recorded in the marker): kept too
    out = work / "out"
    _build_folder(out, photo)
    (out / "interaction.json").write_text("my notes")
    before = _snapshot(work)
    assert main(["check", str(out), "--interact"]) == 3
    assert "interaction.json was not written by scene-builder or was changed since" in capsys.readouterr().err
    assert _snapshot(work) == before


def test_logs_without_a_terminal_are_not_wrapped(monkeypatch):
    import io

    from scene_builder.pipeline import StageLog, stderr_console

    buf = io.StringIO()
    monkeypatch.setattr(sys, "stderr", buf)
    console = stderr_console()
    assert not console.is_terminal and console.soft_wrap
    log = StageLog(True)
    long_detail = "backend reason " * 20 + "[chair] [0, 1]"  # brackets are text, not markup
    with log.stage("perception", lambda: long_detail):
        pass
    lines = buf.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].endswith("[chair] [0, 1]") and len(lines[0]) > 300


# ------------------------------------------------------------------------------------------
# A photo of 500 small objects
# ------------------------------------------------------------------------------------------


def boxes_on_floor_depth_m(n: int = 500, side_m: float = 0.1, w: int = 640, h: int = 480, f: float = 525.0,
                           height_m: float = 1.4, pitch_deg: float = 30.0) -> np.ndarray:
    """(h, w) planar depth of ``n`` cubes of ``side_m`` in a grid on a floor (3.2 x 3.0 m, from
    1.2 m in front of the camera), by ray casting each cube over its projected box only."""
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    d_cam = np.stack([(u - (w - 1) / 2) / f, (v - (h - 1) / 2) / f, np.ones_like(u)], axis=-1)
    p = np.radians(pitch_deg)
    rot = np.stack([[1.0, 0.0, 0.0], [0.0, -np.sin(p), -np.cos(p)], [0.0, np.cos(p), -np.sin(p)]], axis=1)  # world_from_camera
    d = d_cam @ rot.T  # t along d is planar depth (d_cam.z = 1)
    o = np.array([0.0, 0.0, height_m])
    cols = int(np.ceil(np.sqrt(n)))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d[..., 2] < 0, -o[2] / d[..., 2], np.inf)
        for k in range(n):
            i, j = divmod(k, cols)
            centre = np.array([-1.6 + i * 3.2 / (cols - 1), 1.2 + j * 3.0 / (cols - 1)])
            lo = np.array([*(centre - side_m / 2), 0.0])
            hi = np.array([*(centre + side_m / 2), side_m])
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            pc = (corners - o) @ rot
            uu, vv = f * pc[:, 0] / pc[:, 2] + (w - 1) / 2, f * pc[:, 1] / pc[:, 2] + (h - 1) / 2
            u0, u1 = max(0, int(uu.min())), min(w, int(np.ceil(uu.max())) + 1)
            v0, v1 = max(0, int(vv.min())), min(h, int(np.ceil(vv.max())) + 1)
            if u0 >= u1 or v0 >= v1:
                continue
            dd = d[v0:v1, u0:u1]
            t1, t2 = (lo - o) / dd, (hi - o) / dd
            tn, tx = np.nanmax(np.minimum(t1, t2), axis=-1), np.nanmin(np.maximum(t1, t2), axis=-1)
            hit = (tx >= tn) & (tn > 0)
            t[v0:v1, u0:u1] = np.where(hit, np.minimum(t[v0:v1, u0:u1], tn), t[v0:v1, u0:u1])
    t[~np.isfinite(t) | (t > 8.0)] = 0.0
    return t


@pytest.mark.slow
def test_photo_of_500_small_objects_builds_the_largest_and_says_so(work: Path, capsys):
    """What a user expects of a photo with 500 small things: a build in bounded time of the
    largest ``PerceptionConfig.max_objects`` (40), and one line saying how many were left out."""
    from scene_builder.config import PerceptionConfig

    depth = boxes_on_floor_depth_m()
    Image.fromarray((depth * 1000).round().astype(np.uint16)).save(work / "depth.png")
    Image.fromarray(np.full((480, 640, 3), (150, 120, 90), np.uint8)).save(work / "many.png")
    # The depth-cluster segmenter finds every cube (the cap is what is tested, not the detectors,
    # which see nothing in a flat-coloured photo).
    code = main(["many.png", "--depth", "depth.png", "--intrinsics", "525,525,319.5,239.5", "-q", "--viz", "off", "--settle-s", "0.5",
                 "--segmentation-backend", "depth-clusters"])
    err = capsys.readouterr().err
    assert code == 0, err[-2000:]
    cap = PerceptionConfig().max_objects
    report = json.loads((work / "many_scene" / "report.json").read_text())
    assert len(report["objects"]) == cap
    left_out = re.search(rf"warning: (\d+) objects found; the {cap} largest are built and (\d+) smaller ones left out", err)
    assert left_out is not None, err[-2000:]
    assert int(left_out.group(1)) > cap and int(left_out.group(2)) == int(left_out.group(1)) - cap


@pytest.mark.slow
@pytest.mark.xdist_group("nyuv2_metric3d_00000")
def test_real_photo_builds_identical_bytes_twice(tmp_path: Path, built_real_sample):
    """A real RGB-D photo (learned naming, real clutter): the same bytes twice (the first build is
    the session's shared one of the sample, ``built_real_sample``, made the same way)."""
    from scene_builder.config import BuildConfig, ExportConfig, InputSpec
    from scene_builder.pipeline import build

    from .conftest import REAL_DATA, require

    sample = require(REAL_DATA / "nyuv2_metric3d_00000")
    cam = json.loads((sample / "camera.json").read_text())
    inputs = InputSpec(next(sample.glob("rgb.*")), sample / "depth.png", None, (cam["fx"], cam["fy"], cam["cx"], cam["cy"]))
    config = BuildConfig(export=ExportConfig(viz="off"))
    a, b = built_real_sample(sample).out_dir, build(inputs, tmp_path / "b", config).out_dir
    fa, fb = _files(a), _files(b)
    assert sorted(fa) == sorted(fb)
    assert [n for n in fa if fa[n] != fb[n]] == []
