"""``scene-builder batch``: names, manifest, a run killed with SIGKILL and resumed, bad photos that
fail alone, the memory limit, and the Ray path on a local cluster.

Builds use real RGB-D samples downscaled to 160 px wide (about 8 s a build on these machines) so a
dozen items stay affordable; the same code builds full-size photos.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from pathlib import Path

import pytest

from scene_builder import __version__
from scene_builder.batch import MANIFEST, BatchOptions, find_items, run_batch
from scene_builder.bench.batch import write_small_sample
from scene_builder.config import BuildConfig, ExportConfig, InputSpec
from scene_builder.errors import InputError
from scene_builder.pipeline import build, read_marker
from tests.conftest import REPO, real_samples, require, REAL_DATA

#: Build options of the tests: as the CLI's, without the rerun recording (the slowest export).
CONFIG = BuildConfig(export=ExportConfig(viz="off"))
CLI_OPTIONS = ["--viz", "off", "--offline", "-q"]


def _good_inputs(root: Path, n: int) -> list[str]:
    """``n`` small copies of the real samples, every photo called rgb.png in its own folder."""
    samples = real_samples()
    if not samples:
        require(REAL_DATA)
    names = []
    for i in range(n):
        src = samples[i % len(samples)]
        name = f"{i:02d}_{src.name}"
        write_small_sample(src, root / name, 160)
        names.append(name)
    return names


def _bad_inputs(root: Path) -> list[str]:
    """Photos a build must refuse, each failing alone: not an image, an empty file, a truncated
    JPEG, and a depth map of another size than its photo."""
    (root / "bad_text").mkdir(parents=True)
    (root / "bad_text" / "rgb.jpg").write_text("this is not a photo\n")
    (root / "bad_empty").mkdir()
    (root / "bad_empty" / "rgb.png").write_bytes(b"")
    src = real_samples()[0]
    (root / "bad_truncated").mkdir()
    (root / "bad_truncated" / "rgb.jpg").write_bytes((src / "rgb.jpg").read_bytes()[:2000])
    write_small_sample(src, root / "bad_depth_size", 160)
    from PIL import Image

    Image.new("I;16", (37, 23), 2000).save(root / "bad_depth_size" / "depth.png")
    return ["bad_depth_size", "bad_empty", "bad_text", "bad_truncated"]


def _db(out: Path) -> sqlite3.Connection:
    db = sqlite3.connect(f"file:{out / MANIFEST}?mode=ro", uri=True, timeout=10)
    db.row_factory = sqlite3.Row
    return db


def _items(out: Path) -> dict[str, sqlite3.Row]:
    with closing(_db(out)) as db:
        return {r["name"]: r for r in db.execute("SELECT * FROM items")}


def _attempts(out: Path, name: str) -> list[sqlite3.Row]:
    with closing(_db(out)) as db:
        return list(db.execute("SELECT * FROM attempts WHERE name = ? ORDER BY id", (name,)))


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "scene_builder.cli", "batch", *args, *CLI_OPTIONS]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(REPO), "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl"}


def test_names_are_unique_when_every_frame_is_rgb_jpg(tmp_path):
    for rel in ("scans/a/rgb.jpg", "scans/b/rgb.jpg", "scans/b/depth.png", "scans/b/sub/rgb.jpg", "photos/kitchen.jpg", "photos/x.jpg", "photos/x.png"):
        (tmp_path / "in" / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "in" / rel).write_bytes(b"")
    items = {it.name: it for it in find_items(tmp_path / "in")}
    assert sorted(items) == ["photos__kitchen", "photos__x", "photos__x_png", "scans__a", "scans__b", "scans__b__sub"]
    assert items["scans__b"].depth_path == tmp_path / "in" / "scans/b/depth.png"
    assert items["scans__a"].depth_path is None and items["photos__kitchen"].depth_path is None
    listing = tmp_path / "list.txt"
    listing.write_text("# two samples and a photo\nin/scans/a\nin/scans/b/rgb.jpg\n\nin/photos/kitchen.jpg\n")
    assert [it.name for it in find_items(listing)] == ["scans__a", "scans__b", "photos__kitchen"]
    (tmp_path / "one.txt").write_text("in/scans/b\n")
    assert [(it.name, it.depth_path) for it in find_items(tmp_path / "one.txt")] == [("b", tmp_path / "in/scans/b/depth.png")]
    (tmp_path / "bad.txt").write_text("in/photos\n")
    with pytest.raises(InputError, match="holds no rgb.jpg"):
        find_items(tmp_path / "bad.txt")
    with pytest.raises(InputError, match="does not exist"):
        find_items(tmp_path / "nowhere")


def test_output_root_inside_the_input_or_a_foreign_folder_is_refused(tmp_path):
    (tmp_path / "in" / "a").mkdir(parents=True)
    (tmp_path / "in" / "a" / "rgb.jpg").write_bytes(b"")
    with pytest.raises(InputError, match="overlaps the input"):
        run_batch(tmp_path / "in", tmp_path / "in" / "out", CONFIG, BatchOptions(progress=False))
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("keep me")
    with pytest.raises(InputError, match="no manifest.sqlite"):
        run_batch(tmp_path / "in", tmp_path / "mine", CONFIG, BatchOptions(progress=False))
    assert (tmp_path / "mine" / "thesis.tex").read_text() == "keep me"


def test_cli_errors_are_one_line_with_the_input_exit_status(tmp_path, capsys):
    from scene_builder.batch import _lock
    from scene_builder.cli import main

    assert main(["batch", str(tmp_path / "nowhere"), "-o", str(tmp_path / "out"), "--offline"]) == 3
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "does not exist" in err and "\n" not in err
    (tmp_path / "in" / "a").mkdir(parents=True)
    (tmp_path / "in" / "a" / "rgb.jpg").write_bytes(b"")
    (tmp_path / "out").mkdir()
    held = _lock(tmp_path / "out")  # another coordinator holds OUT_ROOT
    try:
        assert main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "out"), "--offline", "-q"]) == 3
        assert "another batch is running" in capsys.readouterr().err
    finally:
        held.close()
    with pytest.raises(SystemExit) as usage:
        main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "out"), "--workers", "0"])
    assert usage.value.code == 2 and "expected 1 or more" in capsys.readouterr().err


def test_ray_auto_without_a_cluster_says_that_ray_local_starts_one(tmp_path):
    """`--ray auto` with no cluster running: one line naming --ray local, exit 3 (Ray's own
    ConnectionError said neither). RAY_TMPDIR keeps Ray from finding a cluster another test
    started on this machine."""
    pytest.importorskip("ray")
    (tmp_path / "in" / "a").mkdir(parents=True)
    (tmp_path / "in" / "a" / "rgb.jpg").write_bytes(b"")  # never read: the cluster is looked for first
    env = {k: v for k, v in _env().items() if k != "RAY_ADDRESS"} | {"RAY_TMPDIR": str(tmp_path / "ray")}
    run = subprocess.run([*_cli(str(tmp_path / "in"), "-o", str(tmp_path / "out"), "--ray", "auto")], env=env,
                         capture_output=True, text=True, timeout=300)
    errors = [line for line in run.stderr.splitlines() if line.startswith("error:")]
    assert run.returncode == 3 and len(errors) == 1, run.stderr[-2000:]
    assert errors[0].startswith("error: --ray auto: no Ray cluster running on this machine (`ray start --head` starts one)")
    assert errors[0].endswith("pass --ray local to start one here for this batch, or leave --ray out for local workers")


def test_resume_adopts_a_complete_output_rebuilds_an_interrupted_item_and_clears_its_staging(tmp_path):
    from scene_builder.batch import Manifest, _remove_stale_staging, plan
    from scene_builder.batch_workers import ItemTask
    from scene_builder.outdir import write_marker

    src, out = tmp_path / "in", tmp_path / "out"
    for name in ("a", "b", "c"):
        (src / name).mkdir(parents=True)
        (src / name / "rgb.jpg").write_bytes(b"")
    out.mkdir()
    items = find_items(src)
    manifest = Manifest(out / MANIFEST)
    manifest.add(items, out)
    run = manifest.start_run("local", 2)
    for it in items[:2]:  # a and b were running when the coordinator was killed
        manifest.start(run, ItemTask(it.name, it.image_path, None, out / it.name, 1))
    # a's build had renamed its folder into place; b's had only its staging folder.
    (out / "a").mkdir()
    (out / "a" / "report.json").write_text(json.dumps({"version": __version__}))
    write_marker(out / "a", InputSpec(src / "a" / "rgb.jpg"))
    (out / ".b.tmp-k2j4").mkdir()
    (out / ".b.tmp-k2j4" / "scene.xml").write_text("<mujoco/>")
    # a folder named like a set-aside output that scene-builder did not write is the user's: kept
    (out / ".c.old-x").mkdir()
    (out / ".c.old-x" / "notes.txt").write_text("mine")
    assert _remove_stale_staging(out, {it.name for it in items}) == 1 and not (out / ".b.tmp-k2j4").exists()
    assert (out / ".c.old-x" / "notes.txt").read_text() == "mine"
    todo, skipped = plan(manifest, items, out, BatchOptions())
    assert [it.name for it in todo] == ["b", "c"] and skipped == 1
    rows = manifest.rows()
    assert (rows["a"]["state"], rows["a"]["version"]) == ("done", __version__)
    assert rows["b"]["state"] == "pending" and rows["c"]["state"] == "pending"
    assert [(a["state"], a["note"].split(":")[0]) for a in _attempts_of(manifest, "a")] == [("done", "adopted")]
    assert [(a["state"], a["note"].split(":")[0]) for a in _attempts_of(manifest, "b")] == [("interrupted", "interrupted")]
    # An output made by an older version is kept unless --since-version asks for newer.
    manifest.db.execute("UPDATE items SET version = '0.0.9' WHERE name = 'a'")
    assert [it.name for it in plan(manifest, items, out, BatchOptions())[0]] == ["b", "c"]
    assert [it.name for it in plan(manifest, items, out, BatchOptions(since_version="0.1.0"))[0]] == ["a", "b", "c"]
    manifest.close()


def _attempts_of(manifest, name: str) -> list:
    return list(manifest.db.execute("SELECT * FROM attempts WHERE name = ? ORDER BY id", (name,)))


def _wait_for(out: Path, proc: subprocess.Popen, done: int, timeout_s: float = 600) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, f"the batch ended before it could be killed: {proc.communicate()[1][-2000:]}"
        if (out / MANIFEST).exists():
            try:
                states = [r["state"] for r in _items(out).values()]
            except sqlite3.OperationalError:
                states = []
            if states.count("done") >= done and "running" in states:
                return
        time.sleep(0.2)
    raise AssertionError("the batch did not get far enough to be killed")


@pytest.mark.slow
def test_batch_killed_with_sigkill_then_resumed_builds_every_good_item_exactly_once(tmp_path):
    import psutil

    src, out = tmp_path / "in", tmp_path / "out"
    good = _good_inputs(src, 6)
    bad = _bad_inputs(src)
    proc = subprocess.Popen(_cli(str(src), "-o", str(out), "--workers", "2"), env=_env(), stderr=subprocess.PIPE, text=True)
    _wait_for(out, proc, done=3)
    workers = psutil.Process(proc.pid).children(recursive=True)
    assert workers, "the batch runs its photos in worker processes"
    before = {n: r["state"] for n, r in _items(out).items()}
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stderr.close()
    # The workers die with their coordinator: none can finish a build behind the resumed run.
    gone, alive = psutil.wait_procs(workers, timeout=20)
    assert not alive, f"workers outlived the killed coordinator: {alive}"
    finished_before = {n for n, s in before.items() if s == "done"}
    interrupted = {n for n, s in before.items() if s == "running"}
    assert len(finished_before) >= 3 and interrupted
    inode = {n: (out / n).stat().st_ino for n in finished_before}

    resumed = subprocess.run(_cli(str(src), "-o", str(out), "--workers", "2"), env=_env(), capture_output=True, text=True, timeout=900)
    assert resumed.returncode == 1, resumed.stderr  # the bad photos failed
    assert f"{len(bad)} of {len(good) + len(bad)} items failed" in resumed.stderr
    items = _items(out)
    assert sorted(items) == sorted(good + bad)
    for name in good:
        row = items[name]
        assert row["state"] == "done" and row["version"] == __version__ and row["error"] is None, dict(row)
        completed = [a for a in _attempts(out, name) if a["state"] == "done"]
        assert len(completed) == 1, (name, [dict(a) for a in _attempts(out, name)])
        marker = read_marker(out / name)
        assert marker is not None and marker["image"] == str((src / name / "rgb.png").resolve())
        assert json.loads((out / name / "report.json").read_text())["version"] == __version__
    for name in finished_before:  # done before the kill: not built again
        assert (out / name).stat().st_ino == inode[name] and len(_attempts(out, name)) == 1
    for name in interrupted:  # running at the kill: recorded as interrupted, then built (or adopted) once
        notes = [a["note"] or "" for a in _attempts(out, name)]
        assert any(n.startswith(("interrupted", "adopted")) for n in notes), notes
    for name in bad:
        assert items[name]["state"] == "failed" and items[name]["error"], dict(items[name])
        assert "\n" not in items[name]["error"]
        assert not (out / name).exists()
    # One output folder per good item, no staging folder left, nothing else (the manifest's WAL
    # files aside).
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith((".", MANIFEST))) == sorted(good)
    assert [p.name for p in out.iterdir() if p.name.startswith(".") and p.name != f".{MANIFEST}.lock"] == []

    # A batch folder is exactly what `build` makes of the same photo.
    direct = build(InputSpec(src / good[0] / "rgb.png", src / good[0] / "depth.png"), tmp_path / "direct", CONFIG)
    assert sorted(p.name for p in direct.out_dir.iterdir()) == sorted(p.name for p in (out / good[0]).iterdir())
    assert (direct.out_dir / "scene.xml").read_text() == (out / good[0] / "scene.xml").read_text()

    # Retrying the failed ones builds nothing good again; --since-version rebuilds an older item.
    retry = subprocess.run(_cli(str(src), "-o", str(out), "--retry-failed"), env=_env(), capture_output=True, text=True, timeout=900)
    assert retry.returncode == 1
    assert all(len(_attempts(out, n)) == 2 and _items(out)[n]["state"] == "failed" for n in bad)
    with closing(sqlite3.connect(out / MANIFEST)) as db, db:
        db.execute("UPDATE items SET version = '0.0.1' WHERE name = ?", (good[0],))
    again = run_batch(src, out, CONFIG, BatchOptions(since_version=__version__, progress=False))
    assert (again.done, again.failed, again.skipped) == (1, 0, len(good) + len(bad) - 1)
    assert _items(out)[good[0]]["version"] == __version__
    assert len([a for a in _attempts(out, good[0]) if a["state"] == "done"]) == 2


@pytest.mark.slow
def test_worker_over_the_memory_limit_is_replaced_and_its_item_failed_with_the_reason(tmp_path):
    src, out = tmp_path / "in", tmp_path / "out"
    good = _good_inputs(src, 1)
    # 0.15 GB: the worker goes over while it loads torch, MuJoCo and the stages.
    summary = run_batch(src, out, CONFIG, BatchOptions(max_worker_memory_gb=0.15, retries=1, progress=False))
    assert (summary.done, summary.failed) == (0, 1)
    row = _items(out)[good[0]]
    assert row["state"] == "failed" and row["attempts"] == 2
    assert "exceeded the memory limit" in row["error"] and "--max-worker-memory-gb" in row["error"]
    assert not (out / good[0]).exists()
    # With room to work, the same item is built on a retry.
    summary = run_batch(src, out, CONFIG, BatchOptions(retry_failed=True, progress=False))
    assert (summary.done, summary.failed) == (1, 0) and read_marker(out / good[0]) is not None


@pytest.mark.slow
def test_ray_path_on_a_local_cluster_builds_the_good_items_and_fails_the_bad_alone(tmp_path):
    ray = pytest.importorskip("ray")
    src, out = tmp_path / "in", tmp_path / "out"
    # One good photo and one bad: the path, not the throughput (one Ray worker warms up once;
    # with two on two cores this test took 5-8 minutes of CI).
    good = _good_inputs(src, 1)
    (src / "bad_text").mkdir()
    (src / "bad_text" / "rgb.jpg").write_text("not a photo")
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, runtime_env={"env_vars": {"PYTHONPATH": str(REPO)}})
    try:
        summary = run_batch(src, out, CONFIG, BatchOptions(workers=1, ray="auto", progress=False))
        assert (summary.done, summary.failed) == (1, 1)
        items = _items(out)
        with closing(_db(out)) as db:
            run = db.execute("SELECT * FROM runs ORDER BY id DESC LIMIT 1").fetchone()
            workers = {r["worker"] for r in db.execute("SELECT worker FROM attempts WHERE state = 'done'")}
        assert run["mode"] == "ray:auto" and run["done"] == 1 and run["failed"] == 1
        # The Ray workers are other processes than this one.
        assert workers and all(w.rsplit(":", 1)[1] != str(os.getpid()) for w in workers)
        for name in good:
            assert items[name]["state"] == "done" and read_marker(out / name) is not None
        assert items["bad_text"]["state"] == "failed" and "cannot read" in items["bad_text"]["error"]
        # A rerun skips every item: no second output, no second build.
        again = run_batch(src, out, CONFIG, BatchOptions(workers=1, ray="auto", progress=False))
        assert (again.done, again.failed, again.skipped) == (0, 0, 2)
    finally:
        ray.shutdown()


def test_a_build_leaves_mujocos_asset_cache_empty(tmp_path):
    """MuJoCo keeps every mesh and texture file it compiled in a process-wide cache (500 MB):
    a build's files come from its staging folder, renamed at the end, so the pipeline empties
    the cache when it is done (a batch worker grew about 80 MB per photo before). Loading the
    built scene.xml afterwards fills the cache again: the cache is on, and the build emptied it."""
    import mujoco

    cache = mujoco.mj_getCache()
    assert mujoco.mj_getCacheCapacity(cache) > 0
    _good_inputs(tmp_path / "src", 1)
    src = next((tmp_path / "src").iterdir())
    result = build(InputSpec(src / "rgb.png", src / "depth.png"), tmp_path / "out", CONFIG)
    assert mujoco.mj_getCacheSize(cache) == 0
    mujoco.MjModel.from_xml_path(str(result.files.mjcf))
    assert mujoco.mj_getCacheSize(cache) > 0


def test_run_item_records_a_refused_photo_and_raises_a_bug(tmp_path, monkeypatch):
    """The errors a build documents (SceneBuilderError; OSError of the machine) are the item's
    one-line error; anything else is a bug and is not dressed up as the photo's fault."""
    import scene_builder.pipeline as pipeline
    from scene_builder.batch_workers import ItemTask, WorkerJob, internal_error, run_item

    monkeypatch.setattr("scene_builder.batch_workers.warm_up", lambda job: 0.0)
    task = ItemTask("a", tmp_path / "a.png", None, tmp_path / "out", 1)

    def refused(*args, **kwargs):
        raise InputError("cannot read a.png as an image (truncated); pass a JPEG or PNG photo")

    monkeypatch.setattr(pipeline, "build", refused)
    outcome = run_item(task, WorkerJob(CONFIG))
    assert (outcome.state, outcome.error) == ("failed", "InputError: cannot read a.png as an image (truncated); pass a JPEG or PNG photo")

    def buggy(*args, **kwargs):
        return {}["missing"]

    monkeypatch.setattr(pipeline, "build", buggy)
    with pytest.raises(KeyError) as bug:
        run_item(task, WorkerJob(CONFIG))
    line = internal_error(bug.value)
    assert line.startswith("internal error (a bug of scene-builder; please report it): KeyError: 'missing' at test_batch.py:")


@pytest.mark.slow
def test_a_bug_in_a_local_worker_fails_its_item_with_the_cause_and_is_not_retried(tmp_path):
    """A worker whose build raises an exception no build documents (here: it was given no
    configuration at all) reports it before it dies; the item fails once with that cause."""
    from PIL import Image

    (tmp_path / "in" / "a").mkdir(parents=True)
    Image.new("RGB", (32, 32)).save(tmp_path / "in" / "a" / "rgb.png")
    summary = run_batch(tmp_path / "in", tmp_path / "out", None, BatchOptions(retries=2, progress=False))
    assert (summary.done, summary.failed) == (0, 1)
    error = _items(tmp_path / "out")["a"]["error"]
    assert error.startswith("internal error (a bug of scene-builder; please report it): AttributeError: ") and "pipeline.py:" in error
    assert len(_attempts(tmp_path / "out", "a")) == 1  # a bug is not retried
