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
    (tmp_path / "groundtruth.json").write_text(json.dumps(data))
    assert readme.rewrite(text, tmp_path) != text
