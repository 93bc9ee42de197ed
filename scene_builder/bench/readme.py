"""README figures from the bench JSON: the README's measured figures are generated, never typed.

Each figure block of README.md sits between ``<!-- bench:NAME -->`` and ``<!-- /bench:NAME -->``
and is rendered from a JSON file the bench wrote into ``bench_results/`` (committed with the code
it measured). ``tests/test_readme_figures.py`` renders every block again and fails when the README
and the JSON drift apart.

    .venv/bin/python -m scene_builder.bench.groundtruth --json bench_results/groundtruth.json
    .venv/bin/python -m scene_builder.bench.novel_view --rooms 4 --json bench_results/novel_view.json
    .venv/bin/python -m scene_builder.bench.cold_start --json bench_results/cold_start.json
    .venv/bin/python -m scene_builder.bench.fronts --json bench_results/fronts.json
    .venv/bin/python -m scene_builder.bench.readme --write     # rewrite the blocks of README.md
    .venv/bin/python -m scene_builder.bench.readme --check     # exit 1 when a block is stale
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

__all__ = ["BLOCKS", "RESULTS", "blocks_in", "render", "rewrite"]

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "bench_results"
README = REPO / "README.md"
_BLOCK = re.compile(r"(<!-- bench:(?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /bench:(?P=name) -->)", re.S)


def _f(x, digits: int = 2) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def _objects(data: dict) -> str:
    """The interactive objects against ground truth (bench.groundtruth), each beside the
    everything-background control."""
    s = data["summary"]
    rows = ["| what is measured (denominator) | interactive objects | control: everything background |", "|---|---:|---:|"]
    sun = s.get("sun-rgbd")
    if sun:
        rows.append(f"| SUN RGB-D with depth: 3D box recall at IoU >= 0.25 (of {sun['true_boxes']} annotated boxes in {sun['inputs']} photos) | {_f(sun['box_recall_iou25'])} | {_f(sun['control_box_recall_iou25'])} |")
        rows.append(f"| ... and the label right | {_f(sun['box_recall_iou25_label'])} | {_f(sun['control_box_recall_iou25_label'])} |")
    plain = s.get("sun-plain")
    if plain:
        rows.append(f"| the same photos without depth: 3D box recall at IoU >= 0.25 (of {plain['true_boxes']}) | {_f(plain['box_recall_iou25'])} | {_f(plain['control_box_recall_iou25'])} |")
        rows.append(f"| ... and the label right | {_f(plain['box_recall_iou25_label'])} | {_f(plain['control_box_recall_iou25_label'])} |")
    coco = s.get("coco")
    if coco:
        people = "people_scored_mask_recall_iou50" in coco  # results before people's pixels were left out have one scoring
        note = ", people's pixels left out" if people else ""
        rows.append(f"| COCO photos (no depth): instance recall at mask IoU >= 0.5, furniture-like classes (of {coco['true_instances']} instances in {coco['inputs']} photos{note}) | {_f(coco['mask_recall_iou50'])} | {_f(coco['control_mask_recall_iou50'])} |")
        rows.append(f"| ... large furniture and appliances (of {coco['true_large_instances']}) | {_f(coco['mask_recall_iou50_large'])} | {_f(coco['control_mask_recall_iou50_large'])} |")
        scored = coco.get("scored_objects", coco["interactive_objects"])
        small = f"; {coco['unscored_small_objects']} smaller than any scored instance left out" if "unscored_small_objects" in coco else ""
        rows.append(f"| ... precision: interactive objects matching an instance at IoU >= 0.25 (of {scored} interactive objects{small}) | {_f(coco['mask_precision_iou25'])} | - |")
        if people:
            rows.append(f"| ... the same three with people's pixels scored (the twin removed them: recall, large, precision) | "
                        f"{_f(coco['people_scored_mask_recall_iou50'])}, {_f(coco['people_scored_mask_recall_iou50_large'])}, {_f(coco['people_scored_mask_precision_iou25'])} | - |")
    real = s.get("real")
    if real:
        rows.append(f"| real RGB-D suite: things a person lists that are interactive objects (of {real.get('inventory_seen', '-')} listed in {real['built']} photos) | {_f(real.get('inventory_instance_recall'))} | 0.00 |")
        rows.append(f"| ... interactive objects that are listed things (precision) | {_f(real.get('inventory_instance_precision'))} | - |")
    lines = ["\n".join(rows), ""]
    physics = any("max_penetration_mm" in (s.get(n) or {}) for n in ("sun-rgbd", "sun-plain", "coco", "real"))
    head = "| set | inputs (built / refused / crashed) | perceived objects | interactive | fixed | background | interactive share of perceived | build seconds, median |"
    rule = "|---|---|---:|---:|---:|---:|---:|---:|"
    if physics:  # results written before the bench recorded each build's physics check have none
        head += " max penetration mm (every build) | builds not at rest |"
        rule += "---:|---:|"
    behind = any("left_out_behind_walls" in (s.get(n) or {}) for n in ("sun-rgbd", "sun-plain", "coco", "real"))
    if behind:  # (results written before perception counted them have none)
        head += " left out behind walls (not perceived) |"
        rule += "---:|"
    unmeasured = any("left_out_unmeasured" in (s.get(n) or {}) for n in ("sun-rgbd", "sun-plain", "coco", "real"))
    if unmeasured:
        head += " left out with too little depth (not perceived) |"
        rule += "---:|"
    fates = [head, rule]
    for name in ("sun-rgbd", "sun-plain", "coco", "real"):
        v = s.get(name)
        if not v:
            continue
        row = (f"| {name} | {v['inputs']} ({v['built']} / {v['refused']} / {v['crashed']}) | {v['perceived_objects']} | {v['interactive_objects']} | "
               f"{v['fixed_objects']} | {v['background_objects']} | {_f(v['interactive_share_of_perceived'])} | {_f(v['build_s_median'], 1)} |")
        if physics:
            row += f" {_f(v.get('max_penetration_mm'), 2)} | {v.get('builds_not_at_rest', '-')} |"
        if behind:
            row += f" {v.get('left_out_behind_walls', '-')} |"
        if unmeasured:
            row += f" {v.get('left_out_unmeasured', '-')} |"
        fates.append(row)
    lines.append("\n".join(fates))
    meta = data.get("meta", {})
    if meta:
        lines.append("")
        lines.append(f"Measured {meta.get('date', '?')} at commit {meta.get('commit', '?')} with `{meta.get('command', '?')}` "
                     f"({meta.get('machine', '?')}; load average {meta.get('load', '?')} at the end).")
    return "\n".join(lines) + "\n"


def _novel_view(data: dict) -> str:
    """The twin from other viewpoints (bench.novel_view) beside its two controls, the shapes by
    the 3D-FRONT protocol, and which targets of issue 25 the figures meet."""
    s = data["summary"]
    rows = ["| share of the other view's valid depth pixels within 10 % (median AbsRel) | twin | photo on a box | everything background |",
            "|---|---:|---:|---:|"]
    mv = s.get("multiview", {}).get("novel")
    if mv:
        pairs = data.get("multiview", [])
        turns = [r["rotation_deg"] for r in pairs]
        moves = [r["translation_m"] for r in pairs]
        rows.append(f"| real frames, {len(pairs)} verified pairs ({min(turns):.0f}-{max(turns):.0f} degree turns, {min(moves):.1f}-{max(moves):.1f} m moves; "
                    f"{mv['twin']['valid_px']} pixels) | " + " | ".join(f"{_f(mv[k]['within10'])} ({_f(mv[k]['absrel_median'], 3)})" for k in ("twin", "box", "background")) + " |")
        rows.append(f"| ... where the input camera saw the point ({_f(mv['twin']['seen_share'])} of them) / had it in view but hidden ({_f(mv['twin']['hidden_share'])}) / "
                    f"out of view ({_f(mv['twin']['outside_share'])}) | " + " | ".join(
                        " / ".join(_f(mv[k][f"within10_{p}"]) for p in ("seen", "hidden", "outside")) for k in ("twin", "box", "background")) + " |")
    pr = s.get("procedural", {}).get("novel")
    if pr:
        rows.append(f"| {len(data.get('procedural', []))} procedural rooms, {pr['twin']['views']} orbit views ({pr['twin']['valid_px']} pixels) | "
                    + " | ".join(f"{_f(pr[k]['within10'])} ({_f(pr[k]['absrel_median'], 3)})" for k in ("twin", "box", "background")) + " |")
    lines = ["\n".join(rows), ""]
    sh = s.get("procedural", {}).get("shapes")
    if sh:
        t, c = sh["twin"], sh["shell"]
        lines.append(f"Shapes against the procedural rooms' true primitives ({t['matched']} of {t['true_objects']} true objects matched), by the single-image "
                     f"3D-FRONT protocol as MIDI's evaluation code computes it: CD-S {_f(t['cd_s'], 3)}, F-Score-S {_f(t['fscore_s'], 1)} %, CD-O {_f(t['cd_o'], 3)}, "
                     f"F-Score-O {_f(t['fscore_o'], 1)} %, IoU-B {_f(t['iou_b'])}; control, the uncompleted depth points of each object: {_f(c['cd_s'], 3)}, "
                     f"{_f(c['fscore_s'], 1)} %, {_f(c['cd_o'], 3)}, {_f(c['fscore_o'], 1)} %, {_f(c['iou_b'])}.")
        lines.append("")
    targets = []
    if mv:
        w, a = mv["twin"]["within10"], mv["twin"]["absrel_median"]
        ok = w >= 0.70 and a <= 0.04
        per = [(r["novel"]["twin"]["within10"], r["novel"]["twin"]["absrel_median"]) for r in data.get("multiview", [])]
        pooled = f"pooled over the pairs {_f(w, 4)} and {_f(a, 4)} ({'both' if ok else 'not both'} within the targets)"
        if per:
            # The issue asks it of every verified pair; three decimals, so that 0.697 does not read 0.70.
            both = sum(pw >= 0.70 and pa <= 0.04 for pw, pa in per)
            targets.append(f"real multi-view pairs within 10 % >= 0.70 and median AbsRel <= 0.04 from every verified pair: "
                           f"**{'met' if both == len(per) else 'not met'}** ({both} of {len(per)} pairs meet both; pair by pair "
                           f"{' / '.join(_f(pw, 3) for pw, _ in per)} within 10 % and AbsRel {' / '.join(_f(pa, 3) for _, pa in per)}); {pooled}")
        else:
            targets.append(f"real multi-view pairs within 10 % >= 0.70 and median AbsRel <= 0.04: {pooled}")
    if pr:
        w = pr["twin"]["within10"]
        targets.append(f"procedural orbit views within 10 % >= 0.85: **{'met' if w >= 0.85 else 'not met'}** ({_f(w, 3)})")
    if targets:
        lines.append("Targets of issue 25: " + "; ".join(targets) + ".")
        lines.append("")
    m = data.get("machine", {})
    lines.append(f"Measured {data.get('date', '?')} at commit {data.get('commit', '?')} with `{data.get('command', '?')}` "
                 f"({m.get('cores', '?')} cores; load average {m.get('load_avg_1m', '?')} at the end; {_f(data.get('seconds'), 0)} s).")
    return "\n".join(lines) + "\n"


def _cold_start(data: dict) -> str:
    """What a user waits for: one build process per photo (bench.cold_start) beside the control."""
    from scene_builder.bench.cold_start import markdown

    return markdown(data)


def _fronts(data: dict) -> str:
    """Doors and drawers against the hand count (bench.fronts) beside the template control."""
    from scene_builder.bench.fronts import markdown

    return markdown(data)


#: block name -> (JSON file under bench_results/, renderer)
BLOCKS = {"objects": ("groundtruth.json", _objects), "novel-view": ("novel_view.json", _novel_view), "cold-start": ("cold_start.json", _cold_start),
          "fronts": ("fronts.json", _fronts)}


def render(name: str, results: Path = RESULTS) -> str:
    """The Markdown of block ``name`` from its JSON file."""
    file, fn = BLOCKS[name]
    return fn(json.loads((results / file).read_text()))


def blocks_in(text: str) -> dict[str, str]:
    """name -> body of every figure block of a README text."""
    return {m.group("name"): m.group("body") for m in _BLOCK.finditer(text)}


def rewrite(text: str, results: Path = RESULTS) -> str:
    """``text`` with every figure block rendered again."""
    return _BLOCK.sub(lambda m: m.group(1) + render(m.group("name"), results) + m.group(4), text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", action="store_true", help="rewrite the figure blocks of README.md")
    mode.add_argument("--check", action="store_true", help="exit 1 when a block differs from its JSON")
    args = parser.parse_args(argv)
    text = README.read_text()
    new = rewrite(text)
    if args.write:
        README.write_text(new)
        return 0
    stale = [n for n, body in blocks_in(text).items() if body != render(n)]
    for n in stale:
        print(f"README block '{n}' differs from bench_results/{BLOCKS[n][0]}: run python -m scene_builder.bench.readme --write")
    return 1 if stale else 0


if __name__ == "__main__":
    raise SystemExit(main())
