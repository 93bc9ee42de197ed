"""Fuzz benchmark of every parser of outside data (issue 12).

    python -m scene_builder.bench.fuzz --n 100000          # all parsers, 100,000 inputs each
    python -m scene_builder.bench.fuzz --n 2000 --only ranges-strict omni-lenient

Parsers (``TARGETS``) and what each may raise, its documented error type:

==================  ==========================================  ==========================
target              parser                                      may raise
==================  ==========================================  ==========================
ranges-strict       ``generation.physx.tokens.decode_ranges``    ``TokenFormatError``
ranges-lenient      ``tokens.decode_ranges_lenient``             nothing
omni-strict         ``tokens.decode_omni``                       ``TokenFormatError``
omni-lenient        ``tokens.decode_omni_lenient``               nothing
description         ``generation.physx.protocol.parse_description``  ``ProtocolError``
basic-info          ``generation.physx.basic_info.description_from_basic_info``  ``ProtocolError``
scene-json          ``scene_builder.serialize.scene_from_json``  ``SceneFileError``
depth-file          ``perception.inputs.load_depth``             ``InputError``
camera-json         ``perception.inputs.read_camera_json``       ``InputError``
image-file          ``perception.inputs.load_rgb``               ``InputError``
==================  ==========================================  ==========================

Inputs are made from seeds (the real recorded PhysX answers in ``../shared/data/physx_protocol``
when present, encodings of random voxel grids, a small scene's ``scene.json``, small PNG / JPEG /
TIFF / .npy files, camera.json files) by byte mutations (flips, deletions, duplications, splices,
truncations, insertions of grammar tokens and extreme numbers: 5000-digit integers, ``1e999``,
``NaN``, negative sizes) and, for JSON, by mutations of the parsed tree (values replaced by other
types, keys dropped, deep nesting). Every input is parsed; an exception outside the target's
allowed types is a crash, reported with the input that caused it. The slowest input per target
bounds the time an input can take (no hangs). While fuzzing, the image size limit of
``perception.inputs`` is lowered to 4 MP so that a mutated header declaring a large image is
decoded in milliseconds (the limit itself is tested by the bad-input catalogue).

Deterministic for a given ``--seed``. The test suite (``tests/test_fuzz_parsers.py``) runs the
same targets under hypothesis with a few thousand inputs.
"""

from __future__ import annotations

import argparse
import base64
import io
import json
import random
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from scene_builder.errors import InputError

SHARED_PROTOCOL = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "physx_protocol"

#: Tokens inserted by mutations: grammar pieces of every parser and numbers at the edges.
EXTREMES = [
    "9" * 5000, "1" + "0" * 30, "-1", "-0", "0", "1e999", "-1e999", "1e-999", "nan", "NaN", "inf", "-inf", "Infinity",
    "2 x 10^99999", "10^-400", "32767", "32768", "4095", "4096", "64", "63", "999999999", "1e308", "4.9e-324",
    "٣", "０", "\x00", "\ufeff", "\r\n", "\n\n", "\t", "'", '"', "\\", "[", "]", "{", "}", ",", ":", ";", "|", "-", "+",
]
GRAMMAR = [
    "l_0: ", "l_1: ", "l_99999999999: ", "group_0: ", "group_1: ", "group_2: ", "['l_0']", "['l_0', 'l_1']", "; Type: E",
    "; Type: C relative to group_0", "; Type: B relative to group_1", "; Type: CB relative to group_0", "; Type: D",
    "; Param: N/A", "; Param: direction: [0, 0, 0]", "direction: [1, 0, 0]", "axis position (in voxel grid): [0, 1, 2]",
    "revolute range (degree): [-122, 0]", "slide range (in voxel grid): [0, 10]", "Dimension: 100*40*80",
    "Name: x\n", "Category: y\n", "Parts: \n", "Group_info: \n", " g/cm^3", " GPa", " kg/m3", ", 1, Wood, 0.7, 10.0, 0.35, d",
    "| 1| Wood| 0.7| 10| 0.3| d", "a:", "b:", "0:layer a", "1:layer b", "63:layer a", "64:layer a", " +[", " -[", "]",
    "0 4096", "4095 1", "12 3;", "l_a", "```", "：", "；", "【", "】", "0-32767", "32767-0", "5-3",
]


@dataclass(frozen=True)
class Target:
    """One parser: ``parse(data)`` on the input bytes; ``allowed`` its documented error types."""

    name: str
    parse: Callable[[bytes], object]
    allowed: tuple[type[BaseException], ...]
    seeds: tuple[bytes, ...]
    json_tree: bool = False  # also mutate the parsed JSON tree of the seeds


@dataclass
class TargetResult:
    name: str
    inputs: int = 0
    accepted: int = 0
    rejected: int = 0
    crashes: int = 0
    seconds: float = 0.0
    slowest_s: float = 0.0
    crash_examples: list[str] = field(default_factory=list)


# ------------------------------------------------------------------------------------------
# Seeds
# ------------------------------------------------------------------------------------------


def _random_grid(rng: np.random.Generator, grid: int) -> np.ndarray:
    occ = np.zeros((grid, grid, grid), dtype=bool)
    for _ in range(int(rng.integers(1, 4))):
        lo = rng.integers(0, grid - 2, 3)
        hi = np.minimum(grid, lo + rng.integers(1, grid // 2, 3))
        occ[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] = True
    return occ


def _protocol_texts(pattern: str) -> list[bytes]:
    if not SHARED_PROTOCOL.is_dir():
        return []
    return [p.read_bytes() for p in sorted(SHARED_PROTOCOL.rglob(pattern))]


def _token_seeds(omni: bool) -> tuple[bytes, ...]:
    from generation.physx.tokens import ANYTHING_GRID, OMNI_GRID, encode_omni, encode_ranges

    rng = np.random.default_rng(0)
    if omni:
        made = [encode_omni(_random_grid(rng, OMNI_GRID), strategy="threshold").encode() for _ in range(6)]
        real = [t for t in _protocol_texts("*omni64.txt")] + [t for t in _protocol_texts("*rle.txt")]
    else:
        made = [encode_ranges(_random_grid(rng, ANYTHING_GRID)).encode() for _ in range(6)]
        real = [t for t in _protocol_texts("*coord_[0-9].txt")]
    return tuple(real + made)


def _description_seeds() -> tuple[bytes, ...]:
    from generation.physx.basic_info import description_from_basic_info
    from generation.physx.description import write_description

    texts = _protocol_texts("*basic_info.txt")
    for raw in _protocol_texts("basic_info.json"):
        desc, _ = description_from_basic_info(json.loads(raw), 64)
        texts.append(write_description(desc).encode())
    if not texts:
        texts.append(
            b"Name: Cabinet\nCategory: Storage\nDimension: 100*40*80\nParts: \n"
            b"l_0: Door, 1, Wood, 0.7 g/cm^3, 10.0, 0.35, the door\nl_1: Frame, 3, Wood, 0.7, 10.0, 0.35, the frame\n"
            b"Group_info: \ngroup_0: ['l_1']; Type: E; Param: N/A\n"
            b"group_1: ['l_0']; Type: C relative to group_0; Param: direction: [1, 0, 0], axis position (in voxel grid): "
            b"[0, 12.95, 17.8], revolute range (degree): [-122, 0]"
        )
    return tuple(texts)


def _basic_info_seeds() -> tuple[bytes, ...]:
    real = _protocol_texts("basic_info.json") + _protocol_texts("*PhysX-Anything-parser.json")
    made = {
        "object_name": "Box", "category": "Storage", "dimension": "40*30*20",
        "parts": [{"label": 0, "name": "Body", "material": "Wood", "density": 0.7, "priority_rank": 3,
                   "Basic_description": "the body", "Young's Modulus (GPa)": 10.0, "Poisson's Ratio": 0.35},
                  {"label": 1, "name": "Lid", "material": "Wood", "density": "0.7 g/cm^3", "priority_rank": 1,
                   "Basic_description": "the lid", "Young's Modulus (GPa)": "10", "Poisson's Ratio": "0.3"}],
        "group_info": {"0": [0], "1": [[1], "0", [1, 0, 0, 0.1, 0.2, 0.3, 0.0, 0.5], "C"]},
    }
    return tuple(real + [json.dumps(made).encode()])


def seed_scene():
    """A small valid Scene (one box on the floor, camera, one wall) for the scene.json seeds."""
    from scene_builder import model

    v = np.array([[x, y, z] for x in (-0.2, 0.2) for y in (-0.1, 0.1) for z in (0.0, 0.3)], dtype=np.float64)
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                  [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]], dtype=np.int64)
    mesh = model.TriangleMesh(v, f)
    material = model.Material("wood", 600.0, 0.5, 0.4, 0.1, 1e10, 0.3)
    mass = 600.0 * 0.4 * 0.2 * 0.3
    inertia = np.diag([mass * (0.2**2 + 0.3**2), mass * (0.4**2 + 0.3**2), mass * (0.4**2 + 0.2**2)]) / 12.0
    part = model.Part("body", None, None, mesh, (mesh,), material, model.Inertial(mass, [0.0, 0.0, 0.15], inertia))
    asset = model.ObjectAsset("box_1", "box", model.AssetKind.RIGID, (part,), [0.4, 0.2, 0.3], backend="fuzz")
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 0.0, 0.0]
    k = model.CameraIntrinsics(525.0, 525.0, 319.5, 239.5, 640, 480, "flag")
    cam_pose = np.array([[0.0, 0.0, 1.0, -1.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 1.4], [0.0, 0.0, 0.0, 1.0]])
    room = model.Room(walls=(model.Plane(np.array([-1.0, 0.0, 0.0]), 3.0, "wall"),))
    return model.Scene(model.Camera(k, cam_pose), room, (model.PlacedObject(asset, pose, "floor"),))


def _scene_seeds() -> tuple[bytes, ...]:
    from scene_builder.serialize import scene_to_json

    return (scene_to_json(seed_scene()).encode(),)


def _file_bytes(save: Callable[[io.BytesIO], None]) -> bytes:
    buf = io.BytesIO()
    save(buf)
    return buf.getvalue()


def _depth_seeds() -> tuple[bytes, ...]:
    from PIL import Image

    rng = np.random.default_rng(0)
    mm = (1000 + 2000 * rng.random((24, 32))).astype(np.uint16)
    out = [
        b"PNG" + _file_bytes(lambda b: Image.fromarray(mm).save(b, format="PNG")),
        b"PNG" + _file_bytes(lambda b: Image.fromarray((mm // 20).astype(np.uint8)).save(b, format="PNG")),
        b"TIF" + _file_bytes(lambda b: Image.fromarray(mm.astype(np.float32) / 1000.0, mode="F").save(b, format="TIFF")),
        b"NPY" + _file_bytes(lambda b: np.save(b, mm.astype(np.float32) / 1000.0)),
        b"NPY" + _file_bytes(lambda b: np.save(b, mm)),
    ]
    return tuple(out)


def _camera_seeds() -> tuple[bytes, ...]:
    return (
        json.dumps({"fx": 518.9, "fy": 519.5, "cx": 325.6, "cy": 253.7, "width": 640, "height": 480}).encode(),
        json.dumps({"fx": 100.0, "fy": 102.0, "cx": 63.5, "cy": 47.5, "width": 128, "height": 96}).encode(),
        json.dumps({"fx": 60, "fy": 60, "cx": 31.5, "cy": 23.5}).encode(),
    )


def _image_seeds() -> tuple[bytes, ...]:
    from PIL import Image

    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 255, (24, 32, 3), dtype=np.uint8)
    exif = Image.Exif()
    exif[0x0112] = 6
    exif.get_ifd(0x8769)[0xA405] = 28
    return (
        _file_bytes(lambda b: Image.fromarray(rgb).save(b, format="PNG")),
        _file_bytes(lambda b: Image.fromarray(rgb).save(b, format="JPEG", quality=80, exif=exif)),
        _file_bytes(lambda b: Image.fromarray(rgb).convert("P").save(b, format="PNG")),
        _file_bytes(lambda b: Image.fromarray(np.dstack([rgb, rgb[:, :, 0]])).save(b, format="PNG")),
        _file_bytes(lambda b: Image.fromarray(rgb).save(b, format="GIF")),
        _file_bytes(lambda b: Image.fromarray(rgb).save(b, format="BMP")),
        _file_bytes(lambda b: Image.fromarray(rgb).convert("CMYK").save(b, format="TIFF")),
    )


# ------------------------------------------------------------------------------------------
# Targets
# ------------------------------------------------------------------------------------------


def _text(data: bytes) -> str:
    return data.decode("utf-8", errors="replace")


def _file_parser(work: Path, read: Callable[[Path], object], default_suffix: str) -> Callable[[bytes], object]:
    """Parse bytes through a file: a 3-byte prefix PNG / TIF / NPY picks the suffix (the seeds have
    one; mutated prefixes fall back to ``default_suffix``)."""
    suffixes = {b"PNG": ".png", b"TIF": ".tif", b"NPY": ".npy"}

    def parse(data: bytes):
        suffix = suffixes.get(data[:3])
        body = data[3:] if suffix else data
        path = work / f"input{suffix or default_suffix}"
        path.write_bytes(body)
        return read(path)

    return parse


def make_targets(work: Path) -> list[Target]:
    """Every parser, with its seeds; file parsers write their input under ``work``."""
    from generation.physx import basic_info as basic_info_json
    from generation.physx import protocol, tokens
    from perception import inputs
    from scene_builder.serialize import SceneFileError, scene_from_json

    def basic_info(data: bytes):
        try:
            doc = json.loads(data)
        except (ValueError, RecursionError):
            return None  # not JSON: not this parser's input
        return basic_info_json.description_from_basic_info(doc, 32)

    return [
        Target("ranges-strict", lambda d: tokens.decode_ranges(_text(d)), (tokens.TokenFormatError,), _token_seeds(False)),
        Target("ranges-lenient", lambda d: tokens.decode_ranges_lenient(_text(d)), (), _token_seeds(False)),
        Target("omni-strict", lambda d: tokens.decode_omni(_text(d)), (tokens.TokenFormatError,), _token_seeds(True)),
        Target("omni-lenient", lambda d: tokens.decode_omni_lenient(_text(d)), (), _token_seeds(True)),
        Target("description", lambda d: protocol.parse_description(_text(d)), (protocol.ProtocolError,), _description_seeds()),
        Target("basic-info", basic_info, (protocol.ProtocolError,), _basic_info_seeds(), json_tree=True),
        Target("scene-json", scene_from_json, (SceneFileError,), _scene_seeds(), json_tree=True),
        Target("depth-file", _file_parser(work, lambda p: inputs.load_depth(p), ".png"), (InputError,), _depth_seeds()),
        Target("camera-json", _file_parser(work, lambda p: inputs.read_camera_json(p, 640, 480), ".json"), (InputError,), _camera_seeds(), json_tree=True),
        Target("image-file", _file_parser(work, lambda p: inputs.load_rgb(p), ".img"), (InputError,), _image_seeds()),
    ]


# ------------------------------------------------------------------------------------------
# Mutations
# ------------------------------------------------------------------------------------------


def mutate_bytes(seed: bytes, rng: random.Random, seeds: tuple[bytes, ...]) -> bytes:
    """1-8 random edits of ``seed``: flips, replacements, deletions, duplications, insertions of
    grammar tokens and extreme numbers, splices with another seed, truncation."""
    b = bytearray(seed)
    for _ in range(rng.randint(1, 8)):
        if not b:
            b = bytearray(rng.choice(seeds)[:64])
            continue
        i = rng.randrange(len(b))
        op = rng.random()
        if op < 0.15:
            b[i] ^= 1 << rng.randrange(8)
        elif op < 0.25:
            b[i] = rng.randrange(256)
        elif op < 0.40:
            del b[i : i + rng.randint(1, 32)]
        elif op < 0.65:
            b[i:i] = rng.choice(EXTREMES if rng.random() < 0.5 else GRAMMAR).encode()
        elif op < 0.78:
            j = rng.randrange(len(b))
            b[i:i] = b[j : j + rng.randint(1, 256)]
        elif op < 0.88:
            other = rng.choice(seeds)
            b = b[:i] + other[rng.randrange(len(other) or 1) :]
        elif op < 0.95:
            del b[i:]
        else:
            # change a run of digits into another number (sizes, labels, indices)
            j = i
            while j < len(b) and 48 <= b[j] <= 57:
                j += 1
            b[i:j] = rng.choice(EXTREMES[:24]).encode()
    return bytes(b)


_JSON_VALUES = [None, True, False, 0, -1, 1, 1e308, -1e308, 2**70, 0.5, "", "x", "nan", "1e999", "9" * 5000, [], {}, [1, 2], {"a": 1}]


def mutate_json(doc, rng: random.Random, rate: float = 0.02, depth: int = 0):
    """A copy of ``doc`` with random nodes (each with probability ``rate``) replaced by other JSON
    values or types, keys dropped or added, lists shortened or grown, occasionally a deeply nested
    value."""
    if depth > 30:
        return doc
    if rng.random() < rate:
        choice = rng.random()
        if choice < 0.1:
            nested: object = 0
            for _ in range(rng.choice([10, 100, 2000])):
                nested = [nested]
            return nested
        return rng.choice(_JSON_VALUES)
    if isinstance(doc, dict):
        out = {}
        for k, v in doc.items():
            if rng.random() < rate:
                continue
            out[k] = mutate_json(v, rng, rate, depth + 1)
        if rng.random() < rate:
            out[rng.choice(["__type__", "label", "extra", "dtype", "shape", "data"])] = rng.choice(_JSON_VALUES)
        return out
    if isinstance(doc, list):
        out = [mutate_json(v, rng, rate, depth + 1) for v in doc if rng.random() > rate]
        if out and rng.random() < rate:
            out.append(rng.choice(out))
        return out
    if isinstance(doc, str) and rng.random() < 3 * rate:
        return mutate_bytes(doc.encode(), rng, (doc.encode() or b"x",)).decode("utf-8", errors="replace")
    return doc


def make_input(target: Target, rng: random.Random, parsed_seeds: list) -> bytes:
    """One input for ``target``: a mutated seed (bytes or, for JSON targets, the tree), now and
    then pure random bytes."""
    r = rng.random()
    if r < 0.03:
        return bytes(rng.randrange(256) for _ in range(rng.randint(0, 300)))
    if target.json_tree and parsed_seeds and r < 0.6:
        try:
            rate = rng.choice([0.001, 0.005, 0.02, 0.08])
            return json.dumps(mutate_json(rng.choice(parsed_seeds), rng, rate)).encode()
        except (ValueError, RecursionError):
            pass
    return mutate_bytes(rng.choice(target.seeds), rng, target.seeds)


# ------------------------------------------------------------------------------------------
# Running
# ------------------------------------------------------------------------------------------


def run_target(target: Target, n: int, seed: int = 0) -> TargetResult:
    """Parse ``n`` inputs; count accepted, rejected (allowed errors) and crashes."""
    import warnings

    rng = random.Random(f"{seed}-{target.name}")
    parsed = []
    if target.json_tree:
        for s in target.seeds:
            try:
                parsed.append(json.loads(s))
            except ValueError:
                pass
    res = TargetResult(target.name)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(n):
            data = make_input(target, rng, parsed)
            t0 = time.perf_counter()
            try:
                target.parse(data)
                res.accepted += 1
            except target.allowed:
                res.rejected += 1
            except Exception as err:  # noqa: BLE001 - a crash is what the fuzzer is looking for
                res.crashes += 1
                if len(res.crash_examples) < 5:
                    tb = traceback.extract_tb(err.__traceback__)[-1]
                    res.crash_examples.append(
                        f"{type(err).__name__}: {str(err)[:120]} at {Path(tb.filename).name}:{tb.lineno}; input {base64.b64encode(data[:200]).decode()}"
                    )
            res.slowest_s = max(res.slowest_s, time.perf_counter() - t0)
            res.inputs += 1
    res.seconds = time.perf_counter() - start
    return res


def markdown(results: list[TargetResult], n: int, seed: int) -> str:
    lines = [
        "| parser | inputs | accepted | rejected (documented error) | crashes | slowest input (s) | inputs/s |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        lines.append(f"| {r.name} | {r.inputs:,} | {r.accepted:,} | {r.rejected:,} | {r.crashes} | {r.slowest_s:.3f} | {r.inputs / max(r.seconds, 1e-9):,.0f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m scene_builder.bench.fuzz", description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=100_000, help="inputs per parser (default 100000)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--only", nargs="*", help="target names (default: all)")
    parser.add_argument("--markdown", type=Path, help="also write the table to this file")
    args = parser.parse_args(argv)
    from perception import inputs

    inputs.MAX_IMAGE_PIXELS = 4_000_000  # see the module doc
    shm = Path("/dev/shm")  # file parsers write every input: in memory when the system has it
    with tempfile.TemporaryDirectory(prefix="scene-builder-fuzz-", dir=shm if shm.is_dir() else None) as tmp:
        targets = [t for t in make_targets(Path(tmp)) if not args.only or t.name in args.only]
        results = []
        for t in targets:
            r = run_target(t, args.n, args.seed)
            results.append(r)
            print(f"{r.name:<15} {r.inputs:>8} inputs  {r.accepted:>8} accepted  {r.rejected:>8} rejected  {r.crashes:>4} crashes  "
                  f"{r.seconds:7.1f} s  slowest {r.slowest_s:.3f} s", file=sys.stderr, flush=True)
            for ex in r.crash_examples:
                print(f"    {ex}", file=sys.stderr)
    table = markdown(results, args.n, args.seed)
    print(table)
    if args.markdown:
        args.markdown.write_text(table + "\n")
    return 1 if any(r.crashes for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
