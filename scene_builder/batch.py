"""Many photos: ``scene-builder batch INPUT -o OUT_ROOT``, a resumable batch of builds.

Every photo becomes ``OUT_ROOT/<name>/`` exactly as ``scene-builder build`` makes it (the same
:func:`scene_builder.pipeline.build`, staging folder renamed into place). ``<name>`` is the photo's
path relative to the input root, with ``/`` written ``__`` (a sample folder's ``rgb.*`` is named
after its folder): unique even when every frame is called ``rgb.jpg``.

The coordinator (this module) alone writes the manifest ``OUT_ROOT/manifest.sqlite`` (SQLite,
WAL): one row per item (state pending / running / done / failed, attempts, timings, error line,
version of scene-builder that built it, output folder), one row per attempt, one per run. A
rerun skips done items, retries failed ones only with ``retry_failed``, rebuilds done items of a
version older than ``since_version``, and resumes a run that was killed: an item left running
is adopted when its output folder is complete (the rename is the last step of a build), else
rebuilt from scratch; stale staging folders are removed first. A lock file keeps a second
coordinator off the same OUT_ROOT. Workers die with the coordinator (see
:mod:`scene_builder.batch_workers`), so no build of a killed run can finish behind a resumed one.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import shutil
import sqlite3
import statistics
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

from scene_builder import __version__
from scene_builder.batch_workers import ItemOutcome, ItemTask, LocalPool, RayPool, WorkerJob
from scene_builder.config import BuildConfig
from scene_builder.errors import InputError

MANIFEST = "manifest.sqlite"
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
#: Names of depth maps in a sample folder (../shared/data/README.md): never photos themselves.
DEPTH_NAMES = ("depth.png",)


@dataclass(frozen=True)
class BatchItem:
    """One photo of a batch: its unique name (a folder name under OUT_ROOT), the photo and its
    depth map (None without one). A ``camera.json`` beside the photo is read by the build."""

    name: str
    image_path: Path
    depth_path: Path | None = None


@dataclass(frozen=True)
class BatchOptions:
    """How to run a batch. workers: local processes (or Ray slots; None = every CPU of the Ray
    cluster). ray: None (local), "local", "auto" or a cluster address. retries: extra attempts
    of an item whose worker died (crash, memory limit) in the same run; a photo the build
    refuses is not retried until ``retry_failed``. max_worker_memory_gb: resident memory limit
    of one worker (None = none)."""

    workers: int = 1
    ray: str | None = None
    retry_failed: bool = False
    since_version: str | None = None
    retries: int = 1
    max_worker_memory_gb: float | None = 8.0
    max_items_per_worker: int | None = None
    overwrite: bool = False
    progress: bool = True


@dataclass(frozen=True)
class BatchSummary:
    """What one run did (also the run's row of the manifest). done / failed count the items this
    run built or failed; skipped the ones it left as they were (done before, or failed before
    without ``retry_failed``). scenes_per_min: done per minute of wall time. overhead_s: median
    per item of the coordinator's wall time from submit to result minus the build's own total.
    warm_s: median seconds a worker spent loading before its first photo. peak_worker_rss_mb:
    the largest resident memory a worker reached."""

    manifest: Path
    total: int
    done: int
    failed: int
    skipped: int
    failed_total: int
    wall_s: float
    scenes_per_min: float
    median_build_s: float | None
    overhead_s: float | None
    warm_s: float | None
    peak_worker_rss_mb: float | None
    errors: tuple[tuple[str, str], ...] = field(default=())


# --------------------------------------------------------------------------- the items


def _sample_item(image: Path) -> tuple[Path | None, bool]:
    """(depth map, is a sample folder) of a photo: ``rgb.*`` beside ``depth.png`` is a sample of
    the ../shared/data layout; a photo called ``rgb.*`` names its folder."""
    depth = image.with_name("depth.png")
    return (depth if depth.is_file() else None), image.stem == "rgb"


def _photos_under(root: Path) -> list[Path]:
    found = []
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for f in sorted(files):
            if f.lower().endswith(IMAGE_SUFFIXES) and f.lower() not in DEPTH_NAMES and not f.startswith("."):
                found.append(Path(folder) / f)
    return found


def _photos_in_list(list_file: Path) -> list[Path]:
    """Paths of a list file, one a line (a photo or a sample folder; relative to the file's
    folder; ``#`` starts a comment)."""
    try:
        text = list_file.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"cannot read the list of photos {list_file} ({err}); pass a folder or a text file with one path a line") from err
    photos = []
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        path = (list_file.parent / line) if not Path(line).is_absolute() else Path(line)
        if path.is_dir():
            inside = [path / f"rgb{s}" for s in IMAGE_SUFFIXES if (path / f"rgb{s}").is_file()]
            if not inside:
                raise InputError(f"{list_file}:{n}: folder {line} holds no rgb.jpg or rgb.png; list photos or sample folders")
            photos.append(inside[0])
        else:
            photos.append(path)  # a missing or corrupt photo fails alone, as its own item
    return photos


def find_items(source: Path) -> tuple[BatchItem, ...]:
    """The photos of ``source`` (a folder searched recursively, or a text file listing photos or
    sample folders), each with its depth map when its folder has one, with unique names."""
    source = Path(source)
    if source.is_dir():
        photos, root = _photos_under(source), source
    elif source.is_file():
        photos = _photos_in_list(source)
        root = Path(os.path.commonpath([p.parent.absolute() for p in photos])) if photos else source.parent
    else:
        raise InputError(f"{source} does not exist; pass a folder of photos or a text file listing them")
    if not photos:
        raise InputError(f"no photos ({', '.join(IMAGE_SUFFIXES)}) under {source}")
    items, seen = [], {}
    for photo in photos:
        depth, sample = _sample_item(photo)
        try:
            rel = photo.absolute().relative_to(root.absolute())
        except ValueError:
            rel = Path(photo.name)
        parts = rel.parent.parts if sample else (*rel.parent.parts, rel.stem)
        if not parts:  # a list of one sample folder: its root is that folder
            parts = (photo.absolute().parent.name,)
        name = "__".join(parts)
        if name in seen:
            name = "__".join((*rel.parent.parts, rel.name.replace(".", "_")))
        if name in seen or not name or name.startswith("."):
            raise InputError(f"{photo} and {seen.get(name, photo)} would share the output folder {name!r}; rename one")
        seen[name] = photo
        items.append(BatchItem(name, photo, depth))
    return tuple(items)


# --------------------------------------------------------------------------- the manifest

_SCHEMA = """
CREATE TABLE IF NOT EXISTS items (
    name TEXT PRIMARY KEY, image TEXT NOT NULL, depth TEXT, state TEXT NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 0, version TEXT, out_dir TEXT NOT NULL, error TEXT,
    build_s REAL, item_s REAL, objects INTEGER, warnings TEXT, updated_at REAL);
CREATE TABLE IF NOT EXISTS attempts (
    id INTEGER PRIMARY KEY AUTOINCREMENT, name TEXT NOT NULL, run INTEGER NOT NULL, attempt INTEGER NOT NULL,
    state TEXT NOT NULL, version TEXT NOT NULL, worker TEXT, started_at REAL NOT NULL, finished_at REAL,
    build_s REAL, item_s REAL, error TEXT, note TEXT, rss_mb REAL, peak_rss_mb REAL, warm_s REAL);
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY AUTOINCREMENT, version TEXT NOT NULL, mode TEXT NOT NULL, workers INTEGER,
    started_at REAL NOT NULL, finished_at REAL, items INTEGER, done INTEGER, failed INTEGER, skipped INTEGER,
    wall_s REAL, scenes_per_min REAL, median_build_s REAL, overhead_s REAL, warm_s REAL,
    peak_worker_rss_mb REAL, load_avg TEXT);
"""


def version_key(version: str) -> tuple[int, ...]:
    """Numeric parts of a version ("0.1.0" -> (0, 1, 0)) for ordering; written here because the
    manifest only holds this project's own plain X.Y.Z versions."""
    return tuple(int(p[:9]) for p in re.findall(r"\d+", version)[:4])


class Manifest:
    """The SQLite manifest of OUT_ROOT; only the coordinator opens it for writing."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        try:
            self.db = sqlite3.connect(self.path, isolation_level=None)
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.executescript(_SCHEMA)
        except sqlite3.DatabaseError as err:
            raise InputError(f"{self.path} is not a batch manifest ({err}); choose another -o or move it away") from err
        self.db.row_factory = sqlite3.Row

    def close(self) -> None:
        self.db.close()

    def rows(self) -> dict[str, sqlite3.Row]:
        return {r["name"]: r for r in self.db.execute("SELECT * FROM items")}

    def add(self, items: tuple[BatchItem, ...], out_root: Path) -> None:
        with self.db:
            for it in items:
                self.db.execute(
                    "INSERT INTO items (name, image, depth, state, out_dir, updated_at) VALUES (?, ?, ?, 'pending', ?, ?) "
                    "ON CONFLICT(name) DO UPDATE SET image = excluded.image, depth = excluded.depth",
                    (it.name, str(it.image_path), None if it.depth_path is None else str(it.depth_path), str(out_root / it.name), time.time()),
                )

    def start_run(self, mode: str, workers: int) -> int:
        cur = self.db.execute("INSERT INTO runs (version, mode, workers, started_at) VALUES (?, ?, ?, ?)", (__version__, mode, workers, time.time()))
        return int(cur.lastrowid)

    def finish_run(self, run: int, summary: BatchSummary) -> None:
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
        self.db.execute(
            "UPDATE runs SET finished_at = ?, items = ?, done = ?, failed = ?, skipped = ?, wall_s = ?, scenes_per_min = ?, "
            "median_build_s = ?, overhead_s = ?, warm_s = ?, peak_worker_rss_mb = ?, load_avg = ? WHERE id = ?",
            (time.time(), summary.total, summary.done, summary.failed, summary.skipped, summary.wall_s, summary.scenes_per_min,
             summary.median_build_s, summary.overhead_s, summary.warm_s, summary.peak_worker_rss_mb, load, run),
        )

    def start(self, run: int, task: ItemTask) -> int:
        with self.db:
            self.db.execute("UPDATE items SET state = 'running', attempts = attempts + 1, updated_at = ? WHERE name = ?", (time.time(), task.name))
            cur = self.db.execute(
                "INSERT INTO attempts (name, run, attempt, state, version, started_at) VALUES (?, ?, ?, 'running', ?, ?)",
                (task.name, run, task.attempt, __version__, time.time()),
            )
        return int(cur.lastrowid)

    def finish(self, attempt_id: int, outcome: ItemOutcome, item_s: float, final: bool) -> None:
        """Record an attempt's outcome; ``final`` = no retry follows (the item's state is set)."""
        now = time.time()
        with self.db:
            self.db.execute(
                "UPDATE attempts SET state = ?, worker = ?, finished_at = ?, build_s = ?, item_s = ?, error = ?, rss_mb = ?, "
                "peak_rss_mb = ?, warm_s = ? WHERE id = ?",
                (outcome.state, outcome.worker, now, outcome.build_s, item_s, outcome.error, outcome.rss_mb, outcome.peak_rss_mb,
                 outcome.warm_s, attempt_id),
            )
            if final or outcome.state == "done":
                self.db.execute(
                    "UPDATE items SET state = ?, version = CASE WHEN ? = 'done' THEN ? ELSE version END, error = ?, build_s = ?, "
                    "item_s = ?, objects = ?, warnings = ?, updated_at = ? WHERE name = ?",
                    (outcome.state, outcome.state, __version__, outcome.error, outcome.build_s, item_s, outcome.objects,
                     "\n".join(outcome.warnings) or None, now, outcome.task.name),
                )

    def set_state(self, name: str, state: str, version: str | None = None, note: str | None = None) -> None:
        with self.db:
            self.db.execute(
                "UPDATE items SET state = ?, version = COALESCE(?, version), error = NULL, updated_at = ? WHERE name = ?",
                (state, version, time.time(), name),
            )
            if note is not None:
                self.db.execute(
                    "UPDATE attempts SET state = ?, finished_at = ?, note = ? WHERE name = ? AND state = 'running'",
                    ("done" if state == "done" else "interrupted", time.time(), note, name),
                )


def _output_version(out_dir: Path, item: BatchItem) -> str | None:
    """The scene-builder version of the complete build of ``item`` in ``out_dir``, or None when
    the folder is absent, incomplete or holds another photo's build."""
    from scene_builder.outdir import read_marker

    marker = read_marker(out_dir)
    if marker is None or marker.get("image") != str(Path(item.image_path).resolve()):
        return None
    try:
        version = json.loads((out_dir / "report.json").read_text()).get("version")
    except (OSError, ValueError, AttributeError):
        return None
    return version if isinstance(version, str) else None


def _remove_stale_staging(out_root: Path, names: set[str]) -> int:
    """Remove staging / set-aside folders a killed build left beside its item's output: a staging
    folder ``.<name>.tmp-*``, and a set-aside previous output ``.<name>.old-*`` only when it is
    scene-builder's (its marker) or empty, as the build only ever sets such a folder aside."""
    from scene_builder.outdir import read_marker

    removed = 0
    for p in sorted(out_root.iterdir()):
        m = re.fullmatch(r"\.(.+)\.(tmp|old)-[^/]+", p.name)
        if not (m and m.group(1) in names and p.is_dir() and not p.is_symlink()):
            continue
        if m.group(2) == "old" and read_marker(p) is None and any(p.iterdir()):
            continue
        shutil.rmtree(p)
        removed += 1
    return removed


def plan(manifest: Manifest, items: tuple[BatchItem, ...], out_root: Path, options: BatchOptions) -> tuple[list[BatchItem], int]:
    """The items this run builds, in input order, and how many it skips. Resumes a killed run first
    (see the module's docstring)."""
    rows = manifest.rows()
    todo, skipped = [], 0
    since = version_key(options.since_version) if options.since_version else None
    for it in items:
        row = rows[it.name]
        out = out_root / it.name
        built = _output_version(out, it)
        state = row["state"]
        if state in ("running", "pending") and built == __version__:
            # A complete output of this version: its build finished before the coordinator stopped
            # (or the manifest was lost); the rename was its last step, so it is whole.
            manifest.set_state(it.name, "done", built, note="adopted: output complete when the run resumed")
            state = "done"
            row = manifest.rows()[it.name]
        elif state == "running":
            manifest.set_state(it.name, "pending", note="interrupted: the run stopped before this build finished; rebuilt")
            state = "pending"
        if state == "done":
            older = since is not None and version_key(row["version"] or "0") < since
            if built is not None and not older:
                skipped += 1
                continue
        elif state == "failed" and not options.retry_failed:
            skipped += 1
            continue
        todo.append(it)
    return todo, skipped


# --------------------------------------------------------------------------- the run


def _lock(out_root: Path):
    handle = open(out_root / f".{MANIFEST}.lock", "w")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        raise InputError(f"another batch is running on {out_root} (its lock is held); wait for it or choose another -o") from None
    return handle


def _check_roots(source: Path, items: tuple[BatchItem, ...], out_root: Path) -> None:
    """Refuse an output root that is, holds or lies inside the input (the folder, or the folders
    of a list's photos), a file, or a folder with content but no manifest."""
    src = Path(source).resolve()
    out = Path(out_root).resolve()
    roots = {src} if src.is_dir() else {Path(it.image_path).resolve().parent for it in items}
    for root in sorted(roots):
        if out == root or root in out.parents or out in root.parents:
            raise InputError(f"output root {out_root} overlaps the input folder {root}; pass -o with a folder outside it")
    if out.exists() and not out.is_dir():
        raise InputError(f"output root {out_root} is a file; pass -o with a folder")
    if out.is_dir() and not (out / MANIFEST).exists() and any(not p.name.startswith(".") for p in out.iterdir()):
        raise InputError(f"output root {out_root} holds files but no {MANIFEST}; choose a new or empty folder, or a batch's earlier -o")


def _make_pool(options: BatchOptions, job: WorkerJob):
    if options.ray is None:
        return LocalPool(options.workers, job, options.max_items_per_worker), options.workers
    pool = RayPool(options.ray, options.workers, job, options.retries, options.max_items_per_worker)
    return pool, pool.slots


def run_batch(source: Path, out_root: Path, config: BuildConfig = BuildConfig(), options: BatchOptions = BatchOptions()) -> BatchSummary:
    """Build every photo of ``source`` into ``out_root/<name>/`` (see the module's docstring) and
    return what this run did; the manifest holds the same figures. Raises InputError (one line)
    for a missing source, an output root inside the input or one that is not a batch's; a photo
    that fails is recorded in the manifest and counted, never raised."""
    from scene_builder.batch_progress import BatchProgress

    out_root = Path(out_root)
    items = find_items(Path(source))
    _check_roots(source, items, out_root)
    out_root.mkdir(parents=True, exist_ok=True)
    lock = _lock(out_root)
    manifest = Manifest(out_root / MANIFEST)
    try:
        manifest.add(items, out_root)
        _remove_stale_staging(out_root, {it.name for it in items})
        todo, skipped = plan(manifest, items, out_root, options)
        limit = None if options.max_worker_memory_gb is None else int(options.max_worker_memory_gb * 1e9)
        # Local workers share this machine's cores; a Ray task has one CPU of its node.
        threads = 1 if options.ray is not None else max(1, (os.cpu_count() or 1) // max(1, options.workers))
        job = WorkerJob(config, options.overwrite, threads, limit)
        mode = "local" if options.ray is None else f"ray:{options.ray}"
        start = time.perf_counter()
        run = manifest.start_run(mode, options.workers)
        with BatchProgress(len(todo), skipped, options.progress) as bar:
            results, stats = _drive(manifest, run, todo, out_root, options, job, bar) if todo else ([], None)
        summary = _summarise(manifest, items, results, skipped, time.perf_counter() - start, stats)
        manifest.finish_run(run, summary)
        if options.progress:
            bar.print_summary(summary)
        return summary
    finally:
        manifest.close()
        lock.close()


@dataclass
class _Result:
    outcome: ItemOutcome
    item_s: float


def _drive(manifest: Manifest, run: int, todo: list[BatchItem], out_root: Path, options: BatchOptions, job: WorkerJob, bar):
    """Feed the pool, record every outcome, retry an item whose worker died."""
    # Absolute paths: a Ray worker's current folder is not the coordinator's.
    queue = deque(
        ItemTask(it.name, Path(it.image_path).absolute(), None if it.depth_path is None else Path(it.depth_path).absolute(), (out_root / it.name).absolute(), 1)
        for it in todo
    )
    pool, _slots = _make_pool(options, job)
    started: dict[str, tuple[int, float]] = {}
    results: list[_Result] = []
    try:
        while queue or pool.busy():
            while queue and pool.free_slots() > 0:
                task = queue.popleft()
                started[task.name] = (manifest.start(run, task), time.perf_counter())
                pool.submit(task)
            for outcome in pool.collect(0.5):
                attempt_id, t0 = started.pop(outcome.task.name)
                item_s = time.perf_counter() - t0
                retry = outcome.state == "failed" and outcome.retryable and options.ray is None and outcome.task.attempt <= options.retries
                manifest.finish(attempt_id, outcome, item_s, final=not retry)
                if retry:
                    t = outcome.task
                    queue.append(ItemTask(t.name, t.image_path, t.depth_path, t.out_dir, t.attempt + 1))
                    continue
                results.append(_Result(outcome, item_s))
                bar.advance(outcome)
    finally:
        pool.close()
    return results, pool.stats


def _median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def _summarise(manifest: Manifest, items, results: list[_Result], skipped: int, wall_s: float, stats) -> BatchSummary:
    done = [r for r in results if r.outcome.state == "done"]
    failed = [r for r in results if r.outcome.state != "done"]
    rows = manifest.rows()
    failed_rows = sorted((n, r["error"] or "") for n, r in rows.items() if r["state"] == "failed" and n in {it.name for it in items})
    overheads = [r.item_s - r.outcome.build_s for r in done if r.outcome.build_s is not None]
    peaks = [r.outcome.peak_rss_mb for r in results if r.outcome.peak_rss_mb is not None]
    return BatchSummary(
        manifest.path,
        len(items),
        len(done),
        len(failed),
        skipped,
        len(failed_rows),
        wall_s,
        60.0 * len(done) / wall_s if wall_s > 0 else 0.0,
        _median([r.outcome.build_s for r in done if r.outcome.build_s is not None]),
        _median(overheads),
        _median(stats.warm_s) if stats is not None else None,
        max(peaks) if peaks else None,
        tuple(failed_rows),
    )
