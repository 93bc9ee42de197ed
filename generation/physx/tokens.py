"""Geometry token encodings of PhysX-Anything (32^3 ranges) and PhysX-Omni (64^3 template RLE).

Both encode one part's occupancy grid, a bool array ``occupancy`` of shape (G, G, G) indexed
``[x, y, z]`` in the PhysX normalised object frame (z up, see ``grid_frame.GridFrame``).

* **Range encoding** (PhysX-Anything, G = 32): voxel (x, y, z) has the linear index
  ``i = x*G*G + y*G + z`` (z fastest). The sorted indices are merged into maximal runs written
  ``N`` (length 1) or ``A-B`` (inclusive), separated by single spaces.
* **Template RLE** (PhysX-Omni, G = 64): the grid is cut into z layers; inside a layer the 2D
  index is ``j = x + G*y`` (x fastest) and the occupied cells are written as maximal runs
  ``start length`` (``start`` alone when length = 1) separated by ``;``. Template lines
  ``<label>:<runs>`` come first, then exactly G layer lines ``<z>:layer <label>[ +[<runs>]][ -[<runs>]]``
  meaning (template runs | added runs) - removed runs, on whole ``(start, length)`` tuples.

The grammar is written down (with real examples) in ``shared/data/physx_protocol/README.md``.
Nothing here imports a heavy library; the run extraction is numpy. The optimal template choice is
a small uncapacitated facility-location problem solved exactly with scipy's HiGHS MILP.

Token counts: the model's real tokenizer (Qwen2.5) is not available offline, so
:func:`count_tokens` counts in two ways that need no vocabulary: ``words`` (whitespace-separated
items: the unit the README uses, e.g. 58 for ``41452_coord_0.txt``), ``units`` (grammar units:
each number, each label or keyword, each punctuation mark and newline) and ``qwen_pretokens`` (the
number of pieces Qwen2's pre-tokenizer splits the text into; it splits every digit on its own, so
this is an exact lower bound of the Qwen2.5 token count: BPE can only merge inside a piece).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

import numpy as np

from scene_builder.errors import InputError

__all__ = [
    "ANYTHING_GRID",
    "OMNI_GRID",
    "TokenCount",
    "TokenFormatError",
    "count_tokens",
    "decode_omni",
    "decode_omni_lenient",
    "decode_ranges",
    "decode_ranges_lenient",
    "encode_occupied_indices",
    "encode_omni",
    "encode_ranges",
    "template_label",
]

ANYTHING_GRID = 32
OMNI_GRID = 64


class TokenFormatError(InputError, ValueError):
    """Geometry token text that does not follow the grammar (one-line message says where)."""


# --------------------------------------------------------------------------------------------
# Token counting
# --------------------------------------------------------------------------------------------

# Qwen2's pre-tokenizer pattern (from the Qwen2 tokenizer's published tokenizer.json); ``\p{..}``
# classes are approximated with Python ``re`` classes, exact for the ASCII text of these grammars.
_QWEN2_PRETOKEN = re.compile(
    r"(?i:'s|'t|'re|'ve|'m|'ll|'d)|[^\r\n\w]?[^\W\d_]+|\d| ?[^\s\w]+[\r\n]*|\s*[\r\n]+|\s+(?!\S)|\s+"
)
_UNIT = re.compile(r"\d+|[^\W\d_]+|\n|[^\s\w]")


@dataclass(frozen=True)
class TokenCount:
    """Size of a token text. words: whitespace-separated items (the README's unit). units: grammar
    units (numbers, words, punctuation marks, newlines). qwen_pretokens: pieces of Qwen2's
    pre-tokenizer, a lower bound of the Qwen2.5 token count. chars: characters."""

    words: int
    units: int
    qwen_pretokens: int
    chars: int


def count_tokens(text: str) -> TokenCount:
    """Count ``text`` in the units of :class:`TokenCount`."""
    return TokenCount(
        words=len(text.split()),
        units=len(_UNIT.findall(text)),
        qwen_pretokens=len(_QWEN2_PRETOKEN.findall(text)),
        chars=len(text),
    )


def _cost_units(text: str) -> int:
    return len(_UNIT.findall(text))


def _cost_qwen(text: str) -> int:
    return len(_QWEN2_PRETOKEN.findall(text))


# --------------------------------------------------------------------------------------------
# Shared helpers
# --------------------------------------------------------------------------------------------


def _check_grid(occupancy: np.ndarray, grid: int) -> np.ndarray:
    occ = np.asarray(occupancy)
    if occ.shape != (grid, grid, grid):
        raise ValueError(f"occupancy must have shape ({grid}, {grid}, {grid}), got {occ.shape}")
    return occ.astype(bool, copy=False)


#: Digit strings longer than this are read as "larger than any grid index" without converting
#: them (Python refuses int() of more than 4300 digits, and no index needs more than 18).
_MAX_DIGITS = 18
_HUGE = 10**_MAX_DIGITS


def _index(digits: str) -> int:
    """The integer of a digit string from model text; anything too long to be an index is _HUGE."""
    return int(digits) if len(digits) <= _MAX_DIGITS else _HUGE


def _runs_1d(flat: np.ndarray) -> np.ndarray:
    """(K, 2) int64 (start, length) of the maximal runs of True in the 1D bool array ``flat``."""
    padded = np.concatenate(([False], flat, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    starts, ends = edges[0::2], edges[1::2]
    return np.stack([starts, ends - starts], axis=1).astype(np.int64)


# --------------------------------------------------------------------------------------------
# PhysX-Anything: 32^3 linear indices merged into ranges
# --------------------------------------------------------------------------------------------


def encode_ranges(occupancy: np.ndarray, grid: int = ANYTHING_GRID) -> str:
    """Range-encode a (G, G, G) bool grid: ``"388-402 1412-1426 17733 ..."`` (canonical form)."""
    occ = _check_grid(occupancy, grid)
    runs = _runs_1d(occ.reshape(-1))  # C order of [x, y, z]: z fastest, as the grammar wants
    return " ".join(str(s) if n == 1 else f"{s}-{s + n - 1}" for s, n in runs.tolist())


def encode_occupied_indices(occupancy: np.ndarray, grid: int = ANYTHING_GRID) -> str:
    """The raw baseline: every occupied linear index (z fastest), space-separated, no merging."""
    occ = _check_grid(occupancy, grid)
    return " ".join(map(str, np.flatnonzero(occ.reshape(-1)).tolist()))


_RANGE_TOKEN = re.compile(r"^([0-9]+)(?:-([0-9]+))?$")


def _range_tokens(text: str, grid: int, lenient: bool) -> tuple[np.ndarray, list[str]]:
    n_cells = grid**3
    flat = np.zeros(n_cells, dtype=bool)
    warnings: list[str] = []
    words = text.split()
    for k, word in enumerate(words):
        m = _RANGE_TOKEN.match(word)
        if m is None:
            if lenient:
                last = k == len(words) - 1
                warnings.append(f"dropped {'truncated last' if last else 'malformed'} token {word[:20]!r} (#{k})")
                continue
            raise TokenFormatError(f"range token #{k} {word[:20]!r} is not N or A-B with non-negative integers")
        a = _index(m.group(1))
        b = _index(m.group(2)) if m.group(2) is not None else a
        if b < a:
            if not lenient:
                raise TokenFormatError(f"range token #{k} {word!r} ends before it starts")
            warnings.append(f"swapped reversed range {word!r}")
            a, b = b, a
        if b >= n_cells:
            if not lenient:
                raise TokenFormatError(f"range token #{k} {word!r} is outside 0..{n_cells - 1} (grid {grid})")
            warnings.append(f"dropped out-of-range part of {word!r} (grid {grid})")
            if a >= n_cells:
                continue
            b = n_cells - 1
        flat[a : b + 1] = True
    return flat.reshape(grid, grid, grid), warnings


def decode_ranges(text: str, grid: int = ANYTHING_GRID) -> np.ndarray:
    """Strict decoder of range tokens: (G, G, G) bool ``[x, y, z]``. Raises TokenFormatError on
    anything outside the grammar (garbage, reversed or out-of-range runs)."""
    occ, _ = _range_tokens(text, grid, lenient=False)
    return occ


def decode_ranges_lenient(text: str, grid: int = ANYTHING_GRID) -> tuple[np.ndarray, tuple[str, ...]]:
    """Tolerant decoder for model output: reversed runs are swapped, malformed or truncated tokens
    dropped, out-of-range indices dropped (the reference decoder clips them to the last voxel,
    which adds a spurious voxel; we drop instead). Returns the grid and what was repaired."""
    occ, warnings = _range_tokens(text, grid, lenient=True)
    return occ, tuple(warnings)


# --------------------------------------------------------------------------------------------
# PhysX-Omni: per-layer 2D RLE with templates
# --------------------------------------------------------------------------------------------

Run = tuple[int, int]


def template_label(k: int) -> str:
    """Bijective base-26 label of the k-th template (0 -> 'a', 25 -> 'z', 26 -> 'aa')."""
    if k < 0:
        raise ValueError("template index must be >= 0")
    out = ""
    k += 1
    while k:
        k, r = divmod(k - 1, 26)
        out = chr(ord("a") + r) + out
    return out


def _fmt_runs(runs) -> str:
    return ";".join(str(s) if n == 1 else f"{s} {n}" for s, n in sorted(runs))


def _layer_runs(occ: np.ndarray, grid: int) -> list[frozenset[Run]]:
    # occ[:, :, z] is indexed [x, y]; transposing to [y, x] and flattening gives j = x + G*y.
    return [frozenset(map(tuple, _runs_1d(occ[:, :, z].T.reshape(-1)).tolist())) for z in range(grid)]


def _layer_line(z: int, label: str, layer: frozenset[Run], template: frozenset[Run]) -> str:
    line = f"{z}:layer {label}"
    add, rem = layer - template, template - layer
    if add:
        line += f" +[{_fmt_runs(add)}]"
    if rem:
        line += f" -[{_fmt_runs(rem)}]"
    return line


def _assign_threshold(layers: list[frozenset[Run]], threshold: float) -> tuple[list[frozenset[Run]], list[int]]:
    """Upstream rule: greedy in z, reuse the best earlier template when |R & T| / max(|R|, |T|) >=
    threshold (ties to the earliest), else the layer becomes a new template."""
    templates: list[frozenset[Run]] = []
    assign: list[int] = []
    for layer in layers:
        best, best_score = -1, -1.0
        for t, tmpl in enumerate(templates):
            denom = max(len(layer), len(tmpl))
            score = 1.0 if denom == 0 else len(layer & tmpl) / denom
            if score > best_score:
                best, best_score = t, score
        if best >= 0 and best_score >= threshold:
            assign.append(best)
        else:
            templates.append(layer)
            assign.append(len(templates) - 1)
    return templates, assign


def _assign_optimal(layers: list[frozenset[Run]], cost) -> tuple[list[frozenset[Run]], list[int]]:
    """Minimum total cost choice of templates among the distinct layers and of each layer's
    template: an uncapacitated facility-location problem, solved exactly as a MILP (HiGHS).

    The label length is taken as one letter (exact up to 26 templates; beyond, it is off by one
    unit per extra letter, which the MILP cannot see without a much larger model)."""
    from scipy.optimize import Bounds, LinearConstraint, milp
    from scipy.sparse import lil_matrix

    cands = sorted(set(layers), key=lambda s: (len(s), sorted(s)))
    n_l, n_c = len(layers), len(cands)
    open_cost = np.array([cost(f"a:{_fmt_runs(c)}\n") for c in cands], dtype=np.float64)
    distinct = {layer: i for i, layer in enumerate(dict.fromkeys(layers))}
    assign_cost_distinct = np.empty((len(distinct), n_c))
    for layer, i in distinct.items():
        for c, tmpl in enumerate(cands):
            assign_cost_distinct[i, c] = cost(_layer_line(0, "a", layer, tmpl) + "\n")
    assign_cost = assign_cost_distinct[[distinct[layer] for layer in layers]]
    # variables: y_c (n_c), then x_{l,c} (n_l * n_c) row-major
    n_var = n_c + n_l * n_c
    objective = np.concatenate([open_cost, assign_cost.reshape(-1)])
    a = lil_matrix((n_l + n_l * n_c, n_var))
    lo = np.empty(n_l + n_l * n_c)
    hi = np.empty(n_l + n_l * n_c)
    for l in range(n_l):  # each layer uses exactly one template
        a[l, n_c + l * n_c : n_c + (l + 1) * n_c] = 1.0
        lo[l], hi[l] = 1.0, 1.0
    row = n_l
    for l in range(n_l):  # x_{l,c} <= y_c
        for c in range(n_c):
            a[row, n_c + l * n_c + c] = 1.0
            a[row, c] = -1.0
            lo[row], hi[row] = -np.inf, 0.0
            row += 1
    res = milp(
        objective,
        constraints=LinearConstraint(a.tocsr(), lo, hi),
        integrality=np.ones(n_var),
        bounds=Bounds(0.0, 1.0),
    )
    if res.x is None:  # pragma: no cover - HiGHS always solves this bounded, feasible problem
        raise RuntimeError(f"template selection MILP failed: {res.message}")
    x = np.round(res.x[n_c:]).reshape(n_l, n_c)
    chosen = x.argmax(axis=1)
    # relabel templates in order of first use
    order: dict[int, int] = {}
    for c in chosen.tolist():
        order.setdefault(c, len(order))
    templates = [cands[c] for c in order]
    return templates, [order[c] for c in chosen.tolist()]


def encode_omni(
    occupancy: np.ndarray,
    grid: int = OMNI_GRID,
    strategy: Literal["optimal", "threshold"] = "optimal",
    threshold: float = 0.5,
    cost: Literal["units", "qwen"] = "units",
) -> str:
    """Template-RLE encode a (G, G, G) bool grid.

    strategy "threshold" reproduces the upstream encoder byte for byte (its training data used
    threshold 0.5); "optimal" picks templates and references that minimise the total count in
    ``cost`` units (grammar units or Qwen2 pre-tokens), solved exactly.
    """
    occ = _check_grid(occupancy, grid)
    layers = _layer_runs(occ, grid)
    if strategy == "threshold":
        templates, assign = _assign_threshold(layers, threshold)
    elif strategy == "optimal":
        templates, assign = _assign_optimal(layers, _cost_units if cost == "units" else _cost_qwen)
    else:
        raise ValueError(f"unknown strategy {strategy!r}; use 'optimal' or 'threshold'")
    labels = [template_label(k) for k in range(len(templates))]
    lines = [f"{labels[k]}:{_fmt_runs(t)}" for k, t in enumerate(templates)]
    lines += [_layer_line(z, labels[t], layers[z], templates[t]) for z, t in enumerate(assign)]
    return "\n".join(lines)


_TEMPLATE_LINE = re.compile(r"^([a-z]+):(.*)$")
_LAYER_LINE = re.compile(r"^([0-9]+):layer ([a-z]+)((?: [+-]\[[^\]]*\])*)$")
_DIFF = re.compile(r" ([+-])\[([^\]]*)\]")
_RUN_ITEM = re.compile(r"^([0-9]+)(?: ([0-9]+))?$")


def _parse_runs(text: str, where: str, n_cells: int, lenient: bool, warnings: list[str]) -> set[Run]:
    runs: set[Run] = set()
    if not text.strip():
        return runs
    for item in re.split(r"[;,]", text):
        m = _RUN_ITEM.match(item.strip())
        if m is None:
            if lenient:
                warnings.append(f"{where}: dropped malformed run {item.strip()[:20]!r}")
                continue
            raise TokenFormatError(f"{where}: run {item.strip()[:20]!r} is not 'start' or 'start length'")
        start, length = _index(m.group(1)), _index(m.group(2) or "1")
        if length < 1 or start + length > n_cells:
            if lenient:
                warnings.append(f"{where}: dropped run {start} {length} outside 0..{n_cells - 1}")
                continue
            raise TokenFormatError(f"{where}: run {start} {length} is outside the layer's cells 0..{n_cells - 1}")
        runs.add((start, length))
    return runs


def _normalise_lenient(text: str) -> str:
    table = str.maketrans({"：": ":", "；": ";", "，": ",", "【": "[", "】": "]", "（": "(", "）": ")"})
    text = text.translate(table).replace("```", "")
    text = re.sub(r"\bl[ _-]([a-z]+)\b", r"layer \1", text)
    text = re.sub(r"\s*([+-])\s*\[\s*", r" \1[", text)
    text = re.sub(r"\s*\]", "]", text)
    return text


def _decode_omni(text: str, grid: int, lenient: bool) -> tuple[np.ndarray, list[str]]:
    n_cells = grid * grid
    warnings: list[str] = []
    if lenient:
        text = _normalise_lenient(text)
    templates: dict[str, set[Run]] = {}
    layer_specs: dict[int, tuple[str, str, int]] = {}
    for n, raw in enumerate(text.split("\n"), start=1):
        line = raw.strip() if lenient else raw
        if not line:
            if lenient:
                continue
            raise TokenFormatError(f"line {n}: empty line (template RLE has no blank lines)")
        lm = _LAYER_LINE.match(line) or (_LAYER_LINE.match(re.sub(r":\s+", ":", line, count=1)) if lenient else None)
        if lm is not None:
            z = _index(lm.group(1))
            if z >= grid:
                if lenient:
                    warnings.append(f"line {n}: dropped layer {z} outside 0..{grid - 1}")
                    continue
                raise TokenFormatError(f"line {n}: layer {z} is outside 0..{grid - 1}")
            if z in layer_specs:
                if lenient:
                    warnings.append(f"line {n}: dropped second line for layer {z}")
                    continue
                raise TokenFormatError(f"line {n}: layer {z} is given twice")
            layer_specs[z] = (lm.group(2), lm.group(3), n)
            continue
        tm = _TEMPLATE_LINE.match(line)
        if tm is not None and not tm.group(2).lstrip().startswith("layer"):
            label = tm.group(1)
            if label in templates:
                if lenient:
                    warnings.append(f"line {n}: dropped second definition of template {label!r}")
                    continue
                raise TokenFormatError(f"line {n}: template {label!r} is defined twice")
            templates[label] = _parse_runs(tm.group(2), f"line {n} (template {label})", n_cells, lenient, warnings)
            continue
        if lenient:
            warnings.append(f"line {n}: dropped unreadable line {line[:30]!r}")
            continue
        raise TokenFormatError(f"line {n}: {line[:30]!r} is neither a template line 'a:runs' nor a layer line 'z:layer a ...'")
    occ = np.zeros((grid, grid, grid), dtype=bool)
    missing = [z for z in range(grid) if z not in layer_specs]
    if missing:
        msg = f"layers {missing[0]}..{missing[-1]} missing ({len(missing)} of {grid}): text truncated?"
        if not lenient:
            raise TokenFormatError(msg)
        warnings.append(msg + " (read as empty)")
    for z, (label, diffs, n) in sorted(layer_specs.items()):
        if label not in templates:
            if lenient:
                warnings.append(f"line {n}: layer {z} refers to missing template {label!r} (read as empty)")
                continue
            raise TokenFormatError(f"line {n}: layer {z} refers to missing template {label!r}")
        runs = set(templates[label])
        adds: set[Run] = set()
        rems: set[Run] = set()
        for sign, body in _DIFF.findall(diffs):
            (adds if sign == "+" else rems).update(_parse_runs(body, f"line {n} (layer {z})", n_cells, lenient, warnings))
        runs = (runs | adds) - rems
        flat = np.zeros(n_cells, dtype=bool)
        for start, length in runs:
            flat[start : start + length] = True
        occ[:, :, z] = flat.reshape(grid, grid).T
    return occ, warnings


def decode_omni(text: str, grid: int = OMNI_GRID) -> np.ndarray:
    """Strict template-RLE decoder: (G, G, G) bool ``[x, y, z]``. Raises TokenFormatError on a
    malformed line, a run outside the layer, a missing template, a repeated or missing layer."""
    occ, _ = _decode_omni(text, grid, lenient=False)
    return occ


def decode_omni_lenient(text: str, grid: int = OMNI_GRID) -> tuple[np.ndarray, tuple[str, ...]]:
    """Tolerant decoder for model output (the reference decoder's tolerances: full-width
    punctuation, code fences, ``l_a`` for ``layer a``, spaces around ``+[``; unreadable lines, bad
    runs, unknown templates and missing layers are skipped). Returns the grid and the repairs."""
    occ, warnings = _decode_omni(text, grid, lenient=True)
    return occ, tuple(warnings)
