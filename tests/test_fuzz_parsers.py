"""Every parser of outside data, fuzzed with hypothesis (issue 12): the geometry token decoders,
the PhysX model text protocol, basic_info.json, scene.json, the depth, camera and image file
readers. Nothing may raise except the parser's documented error type; lenient decoders raise
nothing. About 4,000 inputs in all; ``python -m scene_builder.bench.fuzz`` runs 100,000 per parser.

Inputs: mutations of real seeds (``scene_builder.bench.fuzz``: the recorded PhysX answers, random
voxel encodings, a scene.json, small image / depth / camera files), grammar-aware text and raw
bytes."""

from __future__ import annotations

import json
import random
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scene_builder.bench import fuzz as bench_fuzz
from scene_builder.bench.fuzz import GRAMMAR, EXTREMES, Target, make_input, make_targets

_WORK = Path(tempfile.mkdtemp(prefix="scene-builder-fuzz-test-"))
TARGETS = {t.name: t for t in make_targets(_WORK)}
# derandomize: CI runs the same inputs every time (a rare find must not make CI flaky); the
# benchmark (python -m scene_builder.bench.fuzz --n 100000) explores further.
SETTINGS = settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow], database=None, derandomize=True)


@pytest.fixture(scope="module", autouse=True)
def _small_image_limit():
    """Mutated headers may declare big images; decoding garbage up to 100 MP would be slow (the
    limit itself is tested by the bad-input catalogue)."""
    from perception import inputs

    saved = inputs.MAX_IMAGE_PIXELS
    inputs.MAX_IMAGE_PIXELS = 4_000_000
    yield
    inputs.MAX_IMAGE_PIXELS = saved


def _parsed_seeds(target: Target) -> list:
    out = []
    if target.json_tree:
        for s in target.seeds:
            try:
                out.append(json.loads(s))
            except ValueError:
                pass
    return out


def check(target: Target, data: bytes):
    """Parse ``data``; anything but the documented error fails the test (with the input)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return target.parse(data)
        except target.allowed:
            return None
        except Exception as err:  # pragma: no cover - the failure message is the point
            raise AssertionError(f"{target.name} crashed with {type(err).__name__}: {err} on input {data[:300]!r}") from err


@pytest.mark.parametrize("name", sorted(TARGETS))
@SETTINGS
@given(rng=st.randoms(use_true_random=False))
def test_mutated_seeds_never_crash(name, rng: random.Random):
    target = TARGETS[name]
    check(target, make_input(target, rng, _parsed_seeds(target)))


TOKEN_TEXT = st.lists(st.sampled_from(GRAMMAR + EXTREMES + [" ", "\n", "0", "1", "12", "-", ";", ":layer ", "a"]), max_size=40).map("".join)


@pytest.mark.parametrize("name", ["ranges-strict", "ranges-lenient", "omni-strict", "omni-lenient", "description"])
@settings(max_examples=150, deadline=None, database=None)
@given(text=TOKEN_TEXT | st.text(max_size=200))
def test_grammar_text_never_crashes(name, text: str):
    check(TARGETS[name], text.encode("utf-8", errors="surrogatepass"))


@settings(max_examples=200, deadline=None, database=None)
@given(data=st.binary(max_size=400))
def test_random_bytes_never_crash_the_file_readers(data: bytes):
    for name in ("depth-file", "camera-json", "image-file", "scene-json"):
        check(TARGETS[name], data)


# ------------------------------------------------------------------------------------------
# What the decoders accept is right: round trips on the inputs they accept
# ------------------------------------------------------------------------------------------


@settings(max_examples=150, deadline=None, database=None)
@given(st.lists(st.tuples(st.integers(0, 32**3 - 1), st.integers(1, 40)), max_size=12))
def test_lenient_and_strict_range_decoders_agree_on_clean_text(runs):
    from generation.physx.tokens import decode_ranges, decode_ranges_lenient, encode_ranges

    flat = np.zeros(32**3, dtype=bool)
    for start, length in runs:
        flat[start : start + length] = True
    occ = flat.reshape(32, 32, 32)
    text = encode_ranges(occ)
    strict = decode_ranges(text)
    lenient, repairs = decode_ranges_lenient(text)
    assert repairs == ()
    np.testing.assert_array_equal(strict, occ)
    np.testing.assert_array_equal(lenient, occ)


def test_huge_numbers_are_rejected_not_crashed():
    """5000-digit integers (Python refuses int() of them) and 10^99999 exponents."""
    from generation.physx.protocol import parse_description
    from generation.physx.tokens import TokenFormatError, decode_omni_lenient, decode_ranges, decode_ranges_lenient

    big = "9" * 5000
    with pytest.raises(TokenFormatError, match="outside 0..32767"):
        decode_ranges(f"1-{big}")
    occ, repairs = decode_ranges_lenient(f"3 1-{big} {big}")
    assert occ.sum() == 32**3 - 1 and repairs  # 1..32767 kept, the rest dropped and reported
    occ, repairs = decode_omni_lenient(f"a:{big} 2\n0:layer a")
    assert not occ.any() and any("outside" in r for r in repairs)
    desc, report = parse_description(
        f"Name: x\nDimension: 1*1*1\nParts: \nl_0: body, {big}, wood, 2 x 10^99999, {big}, 0.3, d\n"
        "Group_info: \ngroup_0: ['l_0']; Type: E; Param: N/A"
    )
    part = desc.parts[0]
    assert part.affordance_rank == 5 and part.density_kg_m3 is None and part.youngs_modulus_pa is None
    assert not report.clean


def test_scene_json_names_the_bad_field():
    from scene_builder.serialize import SceneFileError, scene_from_json, scene_to_json

    doc = json.loads(scene_to_json(bench_fuzz.seed_scene()))
    doc["scene"]["objects"][0]["asset"]["parts"][0]["material"]["density_kg_m3"] = "heavy"
    with pytest.raises(SceneFileError, match=r"scene\.json: Scene\.objects\[0\]\.asset\.parts\[0\]\.material\.density_kg_m3 must be a number"):
        scene_from_json(json.dumps(doc))
    doc = json.loads(scene_to_json(bench_fuzz.seed_scene()))
    doc["scene"]["objects"][0]["asset"]["size_m"]["shape"] = [10**12, 10**12]
    with pytest.raises(SceneFileError, match="array shape"):
        scene_from_json(json.dumps(doc))
    assert scene_from_json(scene_to_json(bench_fuzz.seed_scene())).objects[0].name == "box_1"


def test_regressions_found_by_the_fuzz_benchmark(tmp_path):
    """Inputs the 100,000-input benchmark crashed on before they were fixed."""
    from perception.inputs import read_camera_json
    from scene_builder.errors import InputError
    from scene_builder.serialize import SceneFileError, scene_from_json, scene_to_json

    doc = json.loads(scene_to_json(bench_fuzz.seed_scene()))
    faces = doc["scene"]["objects"][0]["asset"]["parts"][0]["visual"]["faces"]
    doc["scene"]["objects"][0]["asset"]["parts"][0]["visual"]["faces"] = {"__ndarray__": True, "dtype": "u1", "shape": [1, 3], "data": [-1, 0, 1]}
    with pytest.raises(SceneFileError, match="does not fit uint8"):
        scene_from_json(json.dumps(doc))
    assert faces  # the seed had faces there
    cam = tmp_path / "camera.json"
    cam.write_text('{"fx": 500, "fy": 500, "cx": 320, "cy": 240, "width": 640, "height": 4' + "9" * 400 + "}")
    with pytest.raises(InputError, match="width and height must be 1..1000000 px"):
        read_camera_json(cam, 640, 480)


def test_regressions_found_with_the_narrowed_error_sets(tmp_path):
    """Inputs the 100,000-input benchmark crashed on once the catch-alls were narrowed (issue 26):
    errors of numpy's .npy reader it does not document, and a mean of +inf and -inf in a PhysX
    quantity (math.fsum raised ValueError, which the old catch-all of the basic_info reader had
    turned into 'does not follow the schema')."""
    from generation.physx.basic_info import description_from_basic_info
    from generation.physx.protocol import ProtocolError
    from perception.inputs import load_depth
    from scene_builder.errors import InputError

    header = "{'descr': '<f4', 'fortran_order': False, 'shape': (24, 32), }"
    for bad, why in (
        (header.replace("'<f4'", "',f4'"), "numpy's dtype string parser, ast.literal_eval: SyntaxError"),
        (header.replace("(24, 32)", "(241" + "0" * 30 + ", 32)"), "memmap: OverflowError"),
    ):
        text = bad.ljust(117) + "\n"
        path = tmp_path / "depth.npy"
        path.write_bytes(b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text.encode() + b"\x00" * 4 * 24 * 32)
        with pytest.raises(InputError, match="cannot read .* as a .npy depth array"):
            load_depth(path)
    data = json.loads(bench_fuzz._basic_info_seeds()[-1])
    data["parts"][0]["density"] = "1e999 and -1e999 g/cm^3"
    desc, report = description_from_basic_info(data, 32)
    assert desc.part(0).density_kg_m3 is None and any("out of range, dropped" in w for w in report.warnings)
    with pytest.raises(ProtocolError):
        description_from_basic_info({"parts": [{"label": 0, "priority_rank": [1]}]}, 32)
