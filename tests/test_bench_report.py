"""scene_builder.bench.report renders the bench JSON it is given (numbers from a real baseline run)."""

from __future__ import annotations

import json

import pytest

from scene_builder.bench import procedural, render, report, suites, truth
from scene_builder.config import BuildConfig
from scene_builder.errors import InputError


def test_report_renders_summary_and_scenes(tmp_path, capsys):
    sample = render.render_room(procedural.make_room(3, n_objects=5), tmp_path / "room")
    scores = suites.evaluate_baseline(suites.oracle_perception(sample), truth.load_truth(sample), tmp_path / "w", BuildConfig())
    scene = suites.SceneResult("room_3", str(sample), 5, 5, True, scores, scores, (("perception", 1.5), ("total", 4.0)), 321.0)
    bad = suites.SceneResult("broken", "x", None, None, False, None, None, (), 321.0, "InputError: no depth")
    scenes = (scene, bad)
    result = suites.BenchResult("synthetic", suites.summarize(scenes, "pipeline"), suites.summarize(scenes, "baseline"), scenes, suites.machine_description(), "2026-11-21T00:00:00+00:00", "scene-builder bench --suite synthetic --rooms 2", tmp_path / "bench.json")
    path = tmp_path / "bench.json"
    path.write_text(json.dumps(result.to_json()))

    assert report.main([str(path)]) == 0
    md = capsys.readouterr().out
    assert "`scene-builder bench --suite synthetic --rooms 2`" in md and "2026-11-21" in md
    assert "## Suite `synthetic`: 2 scenes (1 failed)" in md
    pen_mm = f"{scores.max_penetration_m * 1000:.1f}"
    assert f"| max penetration, median scene (mm) | {pen_mm} | {pen_mm} |" in md
    assert "| broken | failed: InputError: no depth" in md
    assert "room_3 (noisy depth)" in md and f"{scores.n_stable}/{scores.n_free}" in md
    assert "median seconds per stage: perception 1.50, total 4.00".lower() in md.lower()


def test_report_refuses_files_that_are_not_bench_results(tmp_path):
    p = tmp_path / "x.json"
    p.write_text("{}")
    with pytest.raises(InputError):
        report.render([p])
    with pytest.raises(InputError):
        report.render([tmp_path / "missing.json"])


def test_stage_benchmarks_run_in_their_own_process_and_are_pasted_with_their_command(tmp_path):
    ok = report.Extra("Fake table", "prints a table", ("-c", "print('| n | s |'); print('|---|---|'); print('| 10 | 0.2 |')"), markdown=True)
    text = report.Extra("Fake text", "prints text", ("-c", "print('N = 10 took 0.2 s')"))
    bad = report.Extra("Fake failure", "fails", ("-c", "import sys; print('partial'); sys.exit('boom: no data')"))
    runs = [report.run_extra(e) for e in (ok, text, bad)]
    assert [r.returncode for r in runs] == [0, 0, 1]
    assert runs[0].output == "| n | s |\n|---|---|\n| 10 | 0.2 |"
    assert "partial" in runs[2].output and "boom: no data" in runs[2].output
    machine = suites.machine_description()
    md = [report.render_extra(r, machine) for r in runs]
    assert md[0].startswith("## Fake table") and "\n| 10 | 0.2 |\n" in md[0] and "```" not in md[0]
    assert "- command: `python -c print('N = 10 took 0.2 s')`" in md[1] and "```\nN = 10 took 0.2 s\n```" in md[1]
    assert "**Failed (exit status 1)**" in md[2] and "```" in md[2]
    assert {e.argv[e.argv.index("-m") + 1] for e in report.EXTRAS} == {
        "scene_builder.bench.solver", "scene_builder.bench.assets", "scene_builder.bench.tokens", "scene_builder.bench.depth",
        "scene_builder.bench.perception", "scene_builder.bench.single_photo", "scene_builder.bench.detect", "scene_builder.bench.learned", "scene_builder.bench.fuzz",
        "scene_builder.bench.batch",
        "scene_builder.bench.robot",
        "scene_builder.bench.interaction",
        "scene_builder.bench.detectors",
        "scene_builder.bench.outdir",
        "scene_builder.bench.groundtruth",
    }
