"""PhysX geometry token encodings: exact on the real files, lossless on random shapes, clean
errors on malformed text."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from generation.physx.tokens import (
    TokenFormatError,
    count_tokens,
    decode_omni,
    decode_omni_lenient,
    decode_ranges,
    decode_ranges_lenient,
    encode_omni,
    encode_ranges,
    template_label,
)
from tests.conftest import PHYSX_PROTOCOL, require

REAL = [  # part, voxels, bbox min, bbox max (README), 64^3 voxels, bbox min, bbox max
    (0, 519, (0, 10, 4), (31, 12, 18), 4152, (0, 20, 8), (63, 25, 37)),
    (1, 3517, (0, 12, 4), (31, 21, 27), 28136, (0, 24, 8), (63, 43, 55)),
]


def _bbox(occ):
    idx = np.argwhere(occ)
    return tuple(idx.min(0)), tuple(idx.max(0))


@pytest.mark.parametrize("k,n32,lo32,hi32,n64,lo64,hi64", REAL)
def test_real_files_decode_to_readme_counts_and_reencode_identically(k, n32, lo32, hi32, n64, lo64, hi64):
    d = require(PHYSX_PROTOCOL)
    text32 = (d / "PhysX-Anything" / f"41452_coord_{k}.txt").read_text()
    occ32 = decode_ranges(text32)
    assert occ32.sum() == n32 and _bbox(occ32) == (lo32, hi32)
    assert encode_ranges(occ32) == text32
    text64 = (d / "derived" / f"41452_coord_{k}.SYNTHETIC-omni64.txt").read_text()
    occ64 = decode_omni(text64)
    assert occ64.sum() == n64 and _bbox(occ64) == (lo64, hi64)
    assert np.array_equal(occ64, occ32.repeat(2, 0).repeat(2, 1).repeat(2, 2))
    assert encode_omni(occ64, strategy="threshold", threshold=0.5) == text64  # the upstream encoder, byte for byte
    best = encode_omni(occ64)
    assert np.array_equal(decode_omni(best), occ64)
    assert count_tokens(best).units <= count_tokens(text64).units


def test_readme_worked_examples():
    occ = np.zeros((4, 4, 4), bool)
    occ[1:3, 1:3, 1:3] = True
    occ[3, 2, 2] = True
    occ[0, 0, 3] = True
    assert encode_omni(occ, grid=4, strategy="threshold") == "a:\nb:5 2;9 2\nc:0\n0:layer a\n1:layer b\n2:layer b +[9 3] -[9 2]\n3:layer c"
    occ32 = np.zeros((32, 32, 32), bool)
    occ32[0:2, 0:2, 5:8] = True
    occ32[0, 0, 31] = occ32[0, 1, 0] = True
    assert encode_ranges(occ32) == "5-7 31-32 37-39 1029-1031 1061-1063"
    assert count_tokens("388-402 1412-1426").words == 2


def test_template_labels_are_bijective_base_26():
    assert [template_label(k) for k in (0, 25, 26, 27, 701, 702)] == ["a", "z", "aa", "ab", "zz", "aaa"]


def _shape(kind: str, grid: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    g = np.indices((grid,) * 3).transpose(1, 2, 3, 0)
    if kind == "empty":
        return np.zeros((grid,) * 3, bool)
    if kind == "full":
        return np.ones((grid,) * 3, bool)
    if kind == "noise":
        return rng.random((grid,) * 3) < rng.uniform(0.02, 0.6)
    if kind == "sphere":
        c, r = rng.uniform(0, grid, 3), rng.uniform(1, grid / 2)
        d = np.linalg.norm(g + 0.5 - c, axis=-1)
        return (d < r) & (d > r - rng.uniform(1, 3))  # a shell, like PhysX surface voxels
    occ = np.zeros((grid,) * 3, bool)
    for _ in range(rng.integers(1, 6)):  # boxes
        lo = rng.integers(0, grid, 3)
        hi = np.minimum(lo + rng.integers(1, grid, 3), grid)
        occ[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] ^= True
    return occ


SHAPES = st.sampled_from(["empty", "full", "noise", "sphere", "boxes"])


@settings(max_examples=25, deadline=None)
@given(kind=SHAPES, seed=st.integers(0, 2**31), grid=st.sampled_from([8, 16, 32]))
def test_range_encoding_is_lossless(kind, seed, grid):
    occ = _shape(kind, grid, seed)
    text = encode_ranges(occ, grid)
    assert np.array_equal(decode_ranges(text, grid), occ)
    assert count_tokens(text).words == (0 if not occ.any() else len(text.split(" ")))


@settings(max_examples=12, deadline=None)
@given(kind=SHAPES, seed=st.integers(0, 2**31), grid=st.sampled_from([8, 16, 64]))
def test_template_rle_is_lossless_and_optimal_is_never_longer(kind, seed, grid):
    occ = _shape(kind, grid, seed)
    upstream = encode_omni(occ, grid, strategy="threshold")
    best = encode_omni(occ, grid)
    assert np.array_equal(decode_omni(upstream, grid), occ)
    assert np.array_equal(decode_omni(best, grid), occ)
    assert count_tokens(best).units <= count_tokens(upstream).units


BAD_RANGES = ["hello", "1-2-3", "5-3", "40000", "12 -4", "1.5"]


@pytest.mark.parametrize("text", BAD_RANGES)
def test_malformed_range_text_raises_token_format_error(text):
    with pytest.raises(TokenFormatError) as err:
        decode_ranges(text)
    assert isinstance(err.value, ValueError) and "\n" not in str(err.value)


def test_lenient_range_decoder_repairs_and_reports():
    occ, warnings = decode_ranges_lenient("7-5 40000 33-")
    assert sorted(np.flatnonzero(occ.reshape(-1))) == [5, 6, 7]
    assert len(warnings) == 3 and any("truncated" in w for w in warnings)


def _omni_text(*layers: str, templates=("a:", "b:5 2")) -> str:
    lines = list(templates) + [f"{z}:layer a" for z in range(64)]
    for z, line in enumerate(layers):
        lines[len(templates) + z] = line
    return "\n".join(lines)


BAD_OMNI = [
    "garbage",
    _omni_text("0:layer q"),  # missing template
    _omni_text("0:layer b +[4090 10]"),  # run past the layer
    _omni_text("0:layer b +[5 x]"),  # not a run
    _omni_text(templates=("a:",)) + "\n64:layer a",  # layer outside the grid
    "\n".join(_omni_text().split("\n")[:40]),  # truncated
    _omni_text("1:layer a"),  # layer 1 twice, layer 0 missing
    _omni_text(templates=("a:", "a:1")),  # template twice
]


@pytest.mark.parametrize("text", BAD_OMNI)
def test_malformed_template_rle_raises_token_format_error(text):
    with pytest.raises(TokenFormatError) as err:
        decode_omni(text)
    assert "\n" not in str(err.value)


def test_lenient_omni_decoder_reads_reference_variants():
    text = _omni_text("0：l_b + [ 9 3 ] - [5 2]", "1:layer zz")
    occ, warnings = decode_omni_lenient("```\n" + text + "\n```")
    assert occ[:, :, 0].T.reshape(-1).nonzero()[0].tolist() == [9, 10, 11]
    assert not occ[:, :, 1].any() and any("missing template 'zz'" in w for w in warnings)
    truncated, warnings = decode_omni_lenient("\n".join(text.split("\n")[:30]))
    assert any("missing" in w for w in warnings)


def test_bench_counts_and_checks_procedural_shapes():
    from scene_builder.bench.tokens import format_table, measure, procedural_shapes

    shapes = procedural_shapes()
    rows = measure({k: shapes[k] for k in ("chair", "cabinet")}, repeats=1)  # asserts losslessness
    for r in rows:
        assert r["rle-opt"][0] <= r["rle-thr0.5"][0] < r["raw64"][0]
    assert format_table(rows).count("\n") == 3
