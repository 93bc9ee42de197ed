"""Solver timing on synthetic clutter: ``python -m scene_builder.bench.solver [N ...] [--seed S]``.

For each N it builds ``scene_builder.bench.clutter.clutter(N)`` (boxes, random convex pieces, tables with
legs, small boxes on tables, all dropped overlapping), solves it, and prints wall and CPU time,
iterations, penetration before/after and plan displacement; then the growth exponent of the
time, fitted as time ~ N^k over the sizes given.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def bench(n: int, seed: int = 0) -> dict[str, float]:
    """Solve one clutter of ``n`` objects; returns the measured numbers."""
    from layout.solver import solve_layout_with_stats
    from scene_builder.bench.clutter import clutter
    from scene_builder.config import LayoutConfig

    perception, generated = clutter(n, seed)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    result, stats = solve_layout_with_stats(perception, generated, LayoutConfig(), seed=seed)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return {
        "n": n,
        "wall_s": wall,
        "cpu_s": cpu,
        "iterations": result.iterations,
        "converged": float(stats.converged),
        "pen_before_m": result.max_penetration_before_m,
        "pen_after_m": result.max_penetration_after_m,
        "mean_shift_m": stats.mean_shift_m,
        "on_objects": sum(e.parent not in ("floor", "wall") for e in result.support),
        "phases": stats.phase_cpu_s,
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sizes", nargs="*", type=int, default=[10, 50, 200, 1000])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rows = []
    print(f"{'N':>6} {'wall s':>8} {'cpu s':>8} {'iter':>5} {'conv':>5} {'pen before m':>13} {'pen after m':>12} {'mean shift m':>13} {'stacked':>8}")
    for n in args.sizes:
        r = bench(n, args.seed)
        rows.append(r)
        print(
            f"{n:>6d} {r['wall_s']:>8.2f} {r['cpu_s']:>8.2f} {r['iterations']:>5d} {bool(r['converged'])!s:>5} "
            f"{r['pen_before_m']:>13.4f} {r['pen_after_m']:>12.2e} {r['mean_shift_m']:>13.3f} {r['on_objects']:>8d}",
            flush=True,
        )
        print("       cpu by phase: " + ", ".join(f"{k} {v:.2f}" for k, v in r["phases"]), flush=True)
    if len(rows) >= 2:
        n = np.log([r["n"] for r in rows])
        t = np.log([r["cpu_s"] for r in rows])
        k = np.polyfit(n, t, 1)[0]
        print(f"CPU time grows as N^{k:.2f} over N = {', '.join(str(r['n']) for r in rows)}")


if __name__ == "__main__":
    main()
