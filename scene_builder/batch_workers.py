"""Where a batch's photos are built: one item's build (:func:`run_item`) and the two pools that run
it, local worker processes (:class:`LocalPool`) or Ray tasks (:class:`RayPool`).

Both pools have the same four calls (``free_slots``, ``submit``, ``collect``, ``close``) and run
the same :func:`run_item`; only the coordinator of :mod:`scene_builder.batch` writes the manifest.
A worker loads the stages and their heavy libraries once (:func:`warm_up`) and keeps them for
every photo it builds. An item's failure is returned as an :class:`ItemOutcome` with a one-line
error; it never stops the other items.

The local pool is written here rather than taken from ``concurrent.futures.ProcessPoolExecutor``
because killing one worker there breaks the whole pool (every running item is lost): here the
coordinator kills only the worker over its memory limit and starts a fresh one in its place.
"""

from __future__ import annotations

import multiprocessing
import os
import resource
import sys
import time
import warnings
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from pathlib import Path

from scene_builder.config import BuildConfig, InputSpec
from scene_builder.errors import InputError, SceneBuilderError


@dataclass(frozen=True)
class ItemTask:
    """One photo to build: its unique name, its files, where its output goes and which attempt
    this is (1 for the first)."""

    name: str
    image_path: Path
    depth_path: Path | None
    out_dir: Path
    attempt: int


@dataclass(frozen=True)
class WorkerJob:
    """What every worker of a batch shares: the build configuration, ``overwrite`` as in
    ``build --overwrite``, torch threads per worker and the memory limit of one worker (bytes;
    None = no limit)."""

    config: BuildConfig
    overwrite: bool = False
    threads: int = 1
    max_rss_bytes: int | None = None


@dataclass(frozen=True)
class ItemOutcome:
    """What became of one :class:`ItemTask`. state: "done" or "failed". error: one line or None.
    retryable: the worker died (crash, memory limit) rather than the photo being refused.
    build_s: the pipeline's own total (None when it did not finish); warnings: the build's
    InputWarning lines; rss_mb / peak_rss_mb: the worker's resident memory after the item and its
    peak so far; warm_s: seconds this worker spent loading before its first item (0 after)."""

    task: ItemTask
    state: str
    error: str | None = None
    retryable: bool = False
    build_s: float | None = None
    objects: int | None = None
    warnings: tuple[str, ...] = ()
    worker: str = ""
    rss_mb: float | None = None
    peak_rss_mb: float | None = None
    warm_s: float = 0.0


def one_line(text: str) -> str:
    return " ".join(str(text).split())


_WARM_S: float | None = None


def warm_up(job: WorkerJob) -> float:
    """Load the stages and their heavy libraries into this process once; seconds it took (0 when
    this process is already warm)."""
    global _WARM_S
    if _WARM_S is not None:
        return 0.0
    start = time.perf_counter()
    os.environ.setdefault("MUJOCO_GL", "egl")  # as the CLI sets it; a Ray node's worker may not have it
    if job.threads > 0:
        os.environ.setdefault("OMP_NUM_THREADS", str(job.threads))
    from scene_builder.pipeline import load_stages

    load_stages(job.threads)
    _WARM_S = time.perf_counter() - start
    return _WARM_S


def _rss_mb() -> tuple[float, float]:
    """(current, peak) resident memory of this process in MB."""
    import psutil

    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    return psutil.Process().memory_info().rss / 1e6, peak_kib * 1024 / 1e6


def _return_freed_memory() -> None:
    """Hand the heap pages a build freed back to the system (glibc's ``malloc_trim``). glibc keeps
    freed pages in its per-thread arenas (torch, MuJoCo, onnxruntime and rerun run threads), so a
    worker building photo after photo grew from 1.4 to 2.9 GB over 8 builds of one photo, where
    with a trim after each it stays at 0.8-0.9 GB. Does nothing where the C library has no
    ``malloc_trim`` (not glibc)."""
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    trim = getattr(ctypes.CDLL(name), "malloc_trim", None) if name else None
    if trim is not None:
        trim(0)


def run_item(task: ItemTask, job: WorkerJob) -> ItemOutcome:
    """Build one photo into ``task.out_dir`` exactly as ``scene-builder build`` does (staging
    folder renamed into place at the end) and say how it went. What a build raises for a photo
    it cannot build (a ``SceneBuilderError``, or an OSError of the machine: disk full) becomes the
    item's one-line error: in a batch one bad photo must fail alone, and its error is kept in the
    manifest. Anything else is a bug and is raised (a local worker reports it before it dies: see
    :func:`_worker_main`; Ray reports it as the task's error)."""
    from scene_builder.errors import InputWarning
    from scene_builder.pipeline import build

    warm_s = warm_up(job)
    worker = f"{os.uname().nodename}:{os.getpid()}"
    inputs = InputSpec(task.image_path, task.depth_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", InputWarning)
        try:
            result = build(inputs, task.out_dir, job.config, progress=False, overwrite=job.overwrite)
        except (SceneBuilderError, OSError) as err:  # recorded as this item's failure (see the docstring)
            _return_freed_memory()
            rss, peak = _rss_mb()
            return ItemOutcome(task, "failed", f"{type(err).__name__}: {one_line(err)}", worker=worker, rss_mb=rss, peak_rss_mb=peak, warm_s=warm_s)
    lines = tuple(sorted({one_line(w.message) for w in caught if issubclass(w.category, InputWarning)}))
    _return_freed_memory()
    rss, peak = _rss_mb()
    total = dict(result.timings_s).get("total")
    return ItemOutcome(task, "done", None, False, total, len(result.scene.objects), lines, worker, rss, peak, warm_s)


def _die_with_parent(parent_pid: int) -> None:
    """Linux: this process gets SIGKILL when its parent (the coordinator) dies, so a coordinator
    killed mid-run leaves no worker that could still rename an output into place behind the
    resumed run's back."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)


def _worker_main(conn: Connection, job: WorkerJob, parent_pid: int) -> None:
    """A local worker: warm up, say so, then build each task the coordinator sends until None.
    Ctrl-C is the coordinator's to handle (it stops the workers; the manifest keeps the rest)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent(parent_pid)
    warm_s = warm_up(job)
    conn.send(("ready", warm_s))
    while True:
        try:
            task = conn.recv()
        except EOFError:
            return
        if task is None:
            return
        try:
            outcome = run_item(task, job)
        except Exception as err:  # a bug: tell the coordinator what it was and where, then die of it
            conn.send(("crash", internal_error(err)))
            raise
        conn.send(("result", outcome))


def internal_error(err: BaseException) -> str:
    """One line for an item's error when the build hit a bug: the exception, its message and the
    line of scene-builder (or of the library) it came from."""
    import traceback

    frames = traceback.extract_tb(err.__traceback__)
    ours = [f for f in frames if "/site-packages/" not in f.filename] or frames
    where = f" at {Path(ours[-1].filename).name}:{ours[-1].lineno}" if ours else ""
    return f"internal error (a bug of scene-builder; please report it): {type(err).__name__}: {one_line(err)}{where}"[:500]


@dataclass
class _Slot:
    process: multiprocessing.process.BaseProcess
    conn: Connection
    task: ItemTask | None = None
    items: int = 0
    warm_s: float | None = None


@dataclass
class PoolStats:
    """Figures a pool gathers as it runs: warm-up seconds of each worker it started, workers
    restarted over the memory limit or after a crash."""

    warm_s: list[float] = field(default_factory=list)
    killed_for_memory: int = 0
    crashed: int = 0


class LocalPool:
    """``workers`` processes on this machine (spawned: a fresh interpreter, nothing inherited from
    the coordinator but the job). The coordinator watches each worker's resident memory every
    ``collect`` call: a worker over ``job.max_rss_bytes`` is killed and replaced, and its item
    comes back failed and retryable; so does the item of a worker that died. A worker is replaced
    after ``max_items_per_worker`` items (None = never)."""

    def __init__(self, workers: int, job: WorkerJob, max_items_per_worker: int | None = None) -> None:
        self.job = job
        self.max_items = max_items_per_worker
        self.stats = PoolStats()
        self._ctx = multiprocessing.get_context("spawn")
        self._slots: list[_Slot] = [self._start() for _ in range(workers)]

    def _start(self) -> _Slot:
        ours, theirs = self._ctx.Pipe()
        process = self._ctx.Process(target=_worker_main, args=(theirs, self.job, os.getpid()), name="scene-builder-batch-worker")
        process.start()
        theirs.close()
        return _Slot(process, ours)

    def free_slots(self) -> int:
        return sum(1 for s in self._slots if s.task is None)

    def busy(self) -> int:
        return sum(1 for s in self._slots if s.task is not None)

    def submit(self, task: ItemTask) -> None:
        slot = next(s for s in self._slots if s.task is None)
        slot.task = task
        slot.conn.send(task)

    def _replace(self, i: int) -> None:
        old = self._slots[i]
        if old.process.is_alive():
            old.process.kill()
        old.process.join()
        old.conn.close()
        self._slots[i] = self._start()

    def collect(self, timeout_s: float) -> list[ItemOutcome]:
        """Outcomes that arrived within ``timeout_s`` (possibly none), then the memory check."""
        waitables = [s.conn for s in self._slots] + [s.process.sentinel for s in self._slots]
        ready = set(wait(waitables, timeout_s))
        out: list[ItemOutcome] = []
        for i, slot in enumerate(self._slots):
            message = None
            if slot.conn in ready:
                try:
                    message = slot.conn.recv()
                except (EOFError, OSError):
                    message = None
            if message is not None and message[0] == "ready":
                slot.warm_s = message[1]
                self.stats.warm_s.append(message[1])
                continue
            if message is not None and message[0] == "crash":
                # The worker hit a bug and is dying of it; the same photo would hit it again.
                self.stats.crashed += 1
                out.append(ItemOutcome(slot.task, "failed", message[1], retryable=False, worker=str(slot.process.pid)))
                slot.task = None
                self._replace(i)
                continue
            if message is not None:
                outcome: ItemOutcome = message[1]
                slot.task, slot.items = None, slot.items + 1
                out.append(outcome)
                if self.max_items is not None and slot.items >= self.max_items:
                    slot.conn.send(None)
                    self._replace(i)
                continue
            if slot.process.sentinel in ready or not slot.process.is_alive():
                self.stats.crashed += 1
                if slot.warm_s is None:
                    raise SceneBuilderError(
                        f"a batch worker exited (status {slot.process.exitcode}) before it was ready; its error is above. From a "
                        "script, call run_batch under `if __name__ == '__main__':` (workers are spawned and import the main module)"
                    )
                if slot.task is not None:
                    reason = f"worker process died (exit status {slot.process.exitcode}) while building it; restarted"
                    out.append(ItemOutcome(slot.task, "failed", reason, retryable=True, worker=str(slot.process.pid)))
                self._replace(i)
        out.extend(self._check_memory())
        return out

    def _check_memory(self) -> list[ItemOutcome]:
        import psutil

        limit = self.job.max_rss_bytes
        out = []
        if limit is None:
            return out
        for i, slot in enumerate(self._slots):
            try:
                rss = psutil.Process(slot.process.pid).memory_info().rss
            except psutil.Error:
                continue  # it just exited; the next collect sees its sentinel
            if rss <= limit:
                continue
            self.stats.killed_for_memory += 1
            if slot.task is not None:
                reason = f"worker exceeded the memory limit ({rss / 1e9:.2f} GB > {limit / 1e9:.2f} GB) and was restarted; raise --max-worker-memory-gb"
                out.append(ItemOutcome(slot.task, "failed", reason, retryable=True, worker=str(slot.process.pid), rss_mb=rss / 1e6))
            self._replace(i)
        return out

    def close(self) -> None:
        for slot in self._slots:
            try:
                slot.conn.send(None)
            except OSError:
                pass
        for slot in self._slots:
            slot.process.join(timeout=5)
            if slot.process.is_alive():
                slot.process.kill()
                slot.process.join()
            slot.conn.close()


def _watch_memory(limit_bytes: int) -> None:
    """In a Ray worker: end the process when its resident memory exceeds ``limit_bytes`` (Ray then
    retries the task per ``max_retries`` and reports the worker's death)."""
    import threading

    import psutil

    def watch() -> None:
        me = psutil.Process()
        while True:
            rss = me.memory_info().rss
            if rss > limit_bytes:
                print(f"scene-builder batch: worker over the memory limit ({rss / 1e9:.2f} GB > {limit_bytes / 1e9:.2f} GB); exiting", file=sys.stderr)
                os._exit(137)
            time.sleep(0.5)

    threading.Thread(target=watch, daemon=True, name="scene-builder-memory-watch").start()


_WATCHING = False


def ray_run_item(task: ItemTask, job: WorkerJob) -> ItemOutcome:
    """:func:`run_item` as a Ray task: the worker process is reused by Ray for later tasks, so its
    warm-up and memory watch happen once per process."""
    global _WATCHING
    if job.max_rss_bytes is not None and not _WATCHING:
        _watch_memory(job.max_rss_bytes)
        _WATCHING = True
    return run_item(task, job)


class RayPool:
    """The same items as Ray tasks: ``address`` is ``"auto"`` (the running cluster), ``"local"``
    (start one on this machine with ``workers`` CPUs) or a cluster address; a Ray session already
    started by the caller (``ray.init``) is used as it is. One task per item, one CPU each; Ray
    retries a task whose worker died ``retries`` times. Every node must have scene-builder and the
    input and output paths (a shared filesystem)."""

    def __init__(self, address: str, workers: int | None, job: WorkerJob, retries: int, max_items_per_worker: int | None = None) -> None:
        try:
            import ray
        except ImportError as err:  # the optional extra is not installed
            raise InputError(f"--ray needs Ray, which is not installed ({err}); pip install 'scene-builder[ray]'") from err

        self.stats = PoolStats()
        if not ray.is_initialized():
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            if address == "local":
                ray.init(num_cpus=workers or os.cpu_count(), include_dashboard=False, log_to_driver=False)
            else:
                try:
                    ray.init(address=address, log_to_driver=False)
                except ConnectionError as err:  # what ray.init documents for no cluster at the address
                    where = "running on this machine (`ray start --head` starts one)" if address == "auto" else f"at {address}"
                    raise InputError(
                        f"--ray {address}: no Ray cluster {where} ({one_line(err)}); "
                        "pass --ray local to start one here for this batch, or leave --ray out for local workers"
                    ) from err
        self._ray = ray
        cpus = int(ray.cluster_resources().get("CPU", 1))
        self.slots = max(1, min(workers, cpus) if workers else cpus)
        options: dict = {"num_cpus": 1, "max_retries": retries}
        if max_items_per_worker is not None:
            options["max_calls"] = max_items_per_worker
        self._remote = ray.remote(**options)(ray_run_item)
        self._job = ray.put(job)
        self._pending: dict = {}

    def free_slots(self) -> int:
        return self.slots - len(self._pending)

    def busy(self) -> int:
        return len(self._pending)

    def submit(self, task: ItemTask) -> None:
        self._pending[self._remote.remote(task, self._job)] = task

    def collect(self, timeout_s: float) -> list[ItemOutcome]:
        if not self._pending:
            time.sleep(timeout_s)
            return []
        ready, _ = self._ray.wait(list(self._pending), num_returns=len(self._pending), timeout=timeout_s)
        out = []
        for ref in ready:
            task = self._pending.pop(ref)
            try:
                outcome = self._ray.get(ref)
            except self._ray.exceptions.RayError as err:  # the worker died (after Ray's retries)
                self.stats.crashed += 1
                first = one_line(str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__)
                out.append(ItemOutcome(task, "failed", f"Ray task failed: {type(err).__name__}: {first}"[:500]))
                continue
            if outcome.warm_s > 0:
                self.stats.warm_s.append(outcome.warm_s)
            out.append(outcome)
        return out

    def close(self) -> None:
        for ref in list(self._pending):
            self._ray.cancel(ref, force=True)
        self._pending.clear()
