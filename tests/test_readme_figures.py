"""The README's measured figures are generated from the bench JSON in bench_results/ (and never
typed): every figure block renders again to exactly what the README holds."""

from __future__ import annotations

import json

from scene_builder.bench import readme


def test_readme_blocks_match_the_bench_json():
    text = readme.README.read_text()
    blocks = readme.blocks_in(text)
    assert set(blocks) == set(readme.BLOCKS), f"README figure blocks {sorted(blocks)} != generated blocks {sorted(readme.BLOCKS)}"
    for name, body in blocks.items():
        assert body == readme.render(name), f"README block '{name}' drifted from bench_results/{readme.BLOCKS[name][0]}: run python -m scene_builder.bench.readme --write"


def test_a_changed_figure_is_caught(tmp_path):
    """The check is not vacuous: a bench result that changes makes the README stale."""
    src = readme.RESULTS / "groundtruth.json"
    data = json.loads(src.read_text())
    text = readme.README.read_text()
    assert readme.rewrite(text) == text
    first = next(iter(data["summary"].values()))
    first["perceived_objects"] = first["perceived_objects"] + 1
    for other in readme.RESULTS.glob("*.json"):
        (tmp_path / other.name).write_text(other.read_text())
    assert readme.rewrite(text, tmp_path) == text
    (tmp_path / "groundtruth.json").write_text(json.dumps(data))
    assert readme.rewrite(text, tmp_path) != text


def test_novel_view_block_says_met_only_when_the_figures_reach_the_targets(tmp_path):
    """The issue-25 verdict in the README is computed from the bench JSON: moving the real
    multi-view figures across the targets (within 10 % >= 0.70, median AbsRel <= 0.04) flips it."""
    data = json.loads((readme.RESULTS / "novel_view.json").read_text())
    twin = data["summary"]["multiview"]["novel"]["twin"]
    for within10, absrel, verdict in ((0.71, 0.039, "**met**"), (0.71, 0.041, "**not met**"), (0.69, 0.039, "**not met**")):
        twin["within10"], twin["absrel_median"] = within10, absrel
        (tmp_path / "novel_view.json").write_text(json.dumps(data))
        line = next(x for x in readme.render("novel-view", tmp_path).splitlines() if x.startswith("Targets of issue 25"))
        assert line.split(";")[0].endswith(f"{verdict} ({within10:.4f}, {absrel:.4f})")
