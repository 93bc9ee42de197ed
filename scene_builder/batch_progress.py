"""The live view of a batch (rich): a bar with items done and failed, scenes per minute and time
left, then a summary table. Written to stderr like every other message of the CLI."""

from __future__ import annotations

import time

from scene_builder.batch_workers import ItemOutcome


class BatchProgress:
    """``with BatchProgress(total, skipped, show) as bar: bar.advance(outcome)``; nothing is
    printed when ``show`` is False."""

    def __init__(self, total: int, skipped: int, show: bool) -> None:
        self.total, self.skipped, self.show = total, skipped, show
        self.done = self.failed = 0
        self._start = time.perf_counter()
        self._progress = None
        self._task = None
        self._console = None

    def __enter__(self) -> "BatchProgress":
        if not self.show:
            return self
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        from scene_builder.pipeline import stderr_console

        self._console = stderr_console()
        if self.skipped:
            self._console.print(f"{self.skipped} items already done or failed before are skipped")
        self._progress = Progress(
            TextColumn("batch"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("[green]{task.fields[done]} done[/green] [red]{task.fields[failed]} failed[/red]"),
            TextColumn("{task.fields[rate]}"),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=self._console,
        )
        self._progress.__enter__()
        self._task = self._progress.add_task("", total=self.total, done=0, failed=0, rate="")
        return self

    def advance(self, outcome: ItemOutcome) -> None:
        if outcome.state == "done":
            self.done += 1
        else:
            self.failed += 1
        if self._progress is None:
            return
        from rich.markup import escape

        minutes = (time.perf_counter() - self._start) / 60.0
        rate = f"{self.done / minutes:.1f} scenes/min" if minutes > 0 else ""
        self._progress.update(self._task, advance=1, done=self.done, failed=self.failed, rate=rate)
        if outcome.state != "done":
            self._progress.console.print(f"[red]✗[/red] {escape(outcome.task.name)}: {escape(outcome.error or '')}")

    def __exit__(self, *exc) -> bool:
        if self._progress is not None:
            self._progress.__exit__(*exc)
        return False

    def print_summary(self, summary) -> None:
        """The figures of :class:`scene_builder.batch.BatchSummary` as a table."""
        if self._console is None:
            return
        from rich.markup import escape
        from rich.table import Table

        def s(v, fmt: str) -> str:
            return "-" if v is None else format(v, fmt)

        table = Table(title="batch summary", show_header=False)
        table.add_column("what")
        table.add_column("value", justify="right")
        rows = [
            ("items", str(summary.total)),
            ("built in this run", str(summary.done)),
            ("failed in this run", str(summary.failed)),
            ("skipped (done or failed before)", str(summary.skipped)),
            ("failed in the manifest", str(summary.failed_total)),
            ("wall time", f"{summary.wall_s:.1f} s"),
            ("scenes per minute", f"{summary.scenes_per_min:.2f}"),
            ("median build", f"{s(summary.median_build_s, '.1f')} s"),
            ("median overhead per item", f"{s(summary.overhead_s, '.2f')} s"),
            ("worker warm-up (median)", f"{s(summary.warm_s, '.1f')} s"),
            ("peak worker memory", f"{s(summary.peak_worker_rss_mb, '.0f')} MB"),
            ("manifest", escape(str(summary.manifest))),
        ]
        for what, value in rows:
            table.add_row(what, value)
        self._console.print(table)
        for name, error in summary.errors[:10]:
            self._console.print(f"[red]failed[/red] {escape(name)}: {escape(error)}")
        if len(summary.errors) > 10:
            self._console.print(f"... and {len(summary.errors) - 10} more (see the manifest)")
