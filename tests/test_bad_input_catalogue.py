"""The bad-input catalogue (issue 12): every way a user's files and flags can be wrong, through the
command line, each with its expected exit status and its one line ``error: ...`` (and the
``warning: ...`` lines of doubtful input the build goes on with).

Exit statuses: 2 usage error (argparse), 3 input error (``scene_builder.errors.InputError``).

Every case runs ``scene_builder.cli.main`` in-process from a working folder ``work/`` with the
inputs in ``in/``; the base input is a 320x240 RGB-D view of an empty floor (a build of it ends in
perception with "no objects found" in a fraction of a second), so cases whose input is merely
unusual (a 16-bit, grey, palette, CMYK or RGBA photo, conflicting intrinsics) prove the input was
read and perception ran. Nothing may be left behind by a failed build.
"""

from __future__ import annotations

import json
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from PIL import Image

from scene_builder.cli import main

W, H, F = 320, 240, 260.0
K_FLAG = f"{F},{F},{(W - 1) / 2},{(H - 1) / 2}"
NO_OBJECTS = r"no objects found in .*nothing stands out from the floor"


def floor_depth_m(w: int = W, h: int = H, f: float = F, height_m: float = 1.4, pitch_deg: float = 12.0) -> np.ndarray:
    """(h, w) planar depth in metres of an empty floor seen from ``height_m``, pitched down; 0
    where the ray misses the floor within 8 m."""
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    d = np.stack([(u - (w - 1) / 2) / f, (v - (h - 1) / 2) / f, np.ones_like(u)], axis=-1)
    p = np.radians(pitch_deg)
    down = -(d @ np.array([0.0, -np.cos(p), -np.sin(p)]))  # world up in the camera frame
    with np.errstate(divide="ignore"):
        t = np.where(down > 0, height_m / down, 0.0)
    t[t > 8.0] = 0.0
    return t


def _photo(rng_seed: int = 0, w: int = W, h: int = H) -> np.ndarray:
    return np.random.default_rng(rng_seed).integers(60, 200, (h, w, 3), dtype=np.uint8)


def _depth_png(path: Path, depth_units: np.ndarray, dtype=np.uint16) -> Path:
    Image.fromarray(np.asarray(depth_units).astype(dtype)).save(path)
    return path


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def _bomb_png(path: Path, side: int) -> Path:
    """A valid 1-bit PNG of side x side black pixels: a ~100 kB file that decodes to side^2 pixels."""
    row = b"\x00" + bytes((side + 7) // 8)
    c = zlib.compressobj(1)
    data = b"".join([c.compress(row * 500) for _ in range(side // 500)] + [c.compress(row * (side % 500)), c.flush()])
    ihdr = struct.pack(">IIBBBBB", side, side, 1, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", data) + _png_chunk(b"IEND", b""))
    return path


def _jpeg_declaring(path: Path, w: int, h: int) -> Path:
    """A real JPEG whose frame header (SOF0) declares w x h, as a camera's huge photo would."""
    Image.fromarray(_photo(w=64, h=48)).save(path, quality=90)
    raw = bytearray(path.read_bytes())
    sof = raw.index(b"\xff\xc0")
    raw[sof + 5 : sof + 9] = struct.pack(">HH", h, w)
    path.write_bytes(bytes(raw))
    return path


@dataclass
class Env:
    """The folders of one case: ``inp`` holds the base input (photo.png, depth.png), ``work`` is the
    current folder."""

    root: Path
    inp: Path
    work: Path

    @property
    def photo(self) -> str:
        return str(self.inp / "photo.png")

    @property
    def depth(self) -> str:
        return str(self.inp / "depth.png")

    def rgbd(self, *extra: str) -> list[str]:
        return [self.photo, "--depth", self.depth, "--intrinsics", K_FLAG, *extra]


@dataclass
class Case:
    """args(env) -> argv; code: expected exit status; error: regex of the one error line (None:
    success); warnings: regexes of the warning lines before it, in order."""

    id: str
    args: Callable[[Env], list[str]]
    code: int
    error: str | None
    warnings: tuple[str, ...] = field(default_factory=tuple)


def _write(env: Env, name: str, data: bytes | str) -> str:
    p = env.inp / name
    p.write_bytes(data if isinstance(data, bytes) else data.encode())
    return str(p)


def _image_mode(env: Env, name: str, convert: Callable[[Image.Image], Image.Image]) -> list[str]:
    im = convert(Image.fromarray(_photo()))
    path = env.inp / name
    im.save(path)
    return [str(path), "--depth", env.depth, "--intrinsics", K_FLAG]


def _npy(env: Env, name: str, arr: np.ndarray) -> str:
    np.save(env.inp / name, arr)
    return str(env.inp / name)


def _exif_rotated(env: Env) -> list[str]:
    exif = Image.Exif()
    exif[0x0112] = 6  # displayed rotated by 90 degrees
    Image.fromarray(_photo()).save(env.inp / "rotated.jpg", exif=exif)
    return [str(env.inp / "rotated.jpg"), "--depth", env.depth]  # depth is 320x240, the photo shows 240x320


def _camera_json(env: Env, doc) -> None:
    (env.inp / "camera.json").write_text(doc if isinstance(doc, str) else json.dumps(doc))


def _scene_builder_folder(path: Path, image: str) -> None:
    """What an earlier build leaves: report.json, the scene files and the marker (with hashes)."""
    from scene_builder.config import InputSpec
    from scene_builder.outdir import write_marker

    path.mkdir()
    (path / "report.json").write_text("{}\n")
    (path / "scene.xml").write_text("<mujoco/>\n")
    write_marker(path, InputSpec(Path(image)))


def _user_folder(env: Env) -> list[str]:
    precious = env.work / "precious"
    precious.mkdir()
    (precious / "thesis.txt").write_text("four years of work")
    return env.rgbd("-o", str(precious))


def _output_with_user_file(env: Env) -> list[str]:
    out = env.work / "out"
    _scene_builder_folder(out, env.photo)
    (out / "notes.txt").write_text("mine")
    return env.rgbd("-o", str(out))


def _output_with_file_changed(env: Env) -> list[str]:
    out = env.work / "out"
    _scene_builder_folder(out, env.photo)
    (out / "scene.xml").write_text("<mujoco model='mine'/>\n")
    return env.rgbd("-o", str(out))


def _user_folder_overwrite(env: Env) -> list[str]:
    return [*_user_folder(env), "--overwrite"]


def _default_name_taken(env: Env) -> list[str]:
    other = env.root / "other" / "photo.png"
    other.parent.mkdir()
    Image.fromarray(_photo(1)).save(other)
    _scene_builder_folder(env.work / "photo_scene", str(other))
    return env.rgbd()


def _read_only_parent(env: Env) -> list[str]:
    ro = env.root / "readonly"
    ro.mkdir()
    ro.chmod(0o555)
    return env.rgbd("-o", str(ro / "out"))


def _sparse_depth(env: Env) -> list[str]:
    d = np.zeros((H, W), np.uint16)
    d[:5, :50] = 2000
    return [env.photo, "--depth", str(_depth_png(env.inp / "sparse.png", d)), "--intrinsics", K_FLAG]


MM = (floor_depth_m() * 1000.0).round()

CASES = [
    # --- the photo -----------------------------------------------------------------------
    Case("image missing", lambda e: [str(e.inp / "nope.jpg")], 3, r"image not found: .*nope\.jpg \(check the path\)"),
    Case("image is a folder", lambda e: [str(e.inp)], 3, r"image .* is a folder; pass the photo file inside it"),
    Case("image empty file", lambda e: [_write(e, "empty.jpg", b"")], 3, r"cannot read .*empty\.jpg as an image \(.*\); pass a JPEG or PNG"),
    Case("image not an image", lambda e: [_write(e, "notes.jpg", "this is not a picture")], 3, r"cannot read .*notes\.jpg as an image"),
    Case(
        "image truncated",
        lambda e: [_write(e, "cut.jpg", (Image.fromarray(_photo()).save(e.inp / "full.jpg"), (e.inp / "full.jpg").read_bytes())[1][:3000])],
        3,
        r"cannot read .*cut\.jpg as an image \(image file is truncated.*\)",
    ),
    Case("image tiny", lambda e: [(Image.fromarray(_photo(w=8, h=8)).save(e.inp / "t.png"), str(e.inp / "t.png"))[1]], 3, r"only 8x8 px; pass a photo of at least 16x16"),
    Case("decompression bomb", lambda e: [str(_bomb_png(e.inp / "bomb.png", 15000))], 3, r"image .*bomb\.png is too large to read .*at most 100 MP"),
    Case("20000x20000 photo", lambda e: [str(_jpeg_declaring(e.inp / "huge.jpg", 20000, 20000))], 3, r"huge\.jpg is too large to read .*at most 100 MP"),
    Case("121 MP photo", lambda e: [str(_jpeg_declaring(e.inp / "big.jpg", 11000, 11000))], 3, r"big\.jpg is 11000x11000 px \(121 MP\); .*at most 100 MP: downscale it first"),
    Case(
        "EXIF-rotated photo, depth not rotated",
        _exif_rotated,
        3,
        r"depth map .* is 320x240 px but the image is 240x320 px; it matches the image as stored, before its EXIF orientation",
    ),
    Case("16-bit grey photo", lambda e: _image_mode(e, "g16.png", lambda im: Image.fromarray((np.asarray(im.convert("L")).astype(np.uint16) * 257))), 3, NO_OBJECTS, (r"g16\.png is a I;16 grey image .*Is it a depth map\? Pass it with --depth",)),
    Case("grey photo", lambda e: _image_mode(e, "grey.png", lambda im: im.convert("L")), 3, NO_OBJECTS),
    Case("palette photo", lambda e: _image_mode(e, "pal.png", lambda im: im.convert("P")), 3, NO_OBJECTS),
    Case("CMYK photo", lambda e: _image_mode(e, "cmyk.jpg", lambda im: im.convert("CMYK")), 3, NO_OBJECTS),
    Case(
        "RGBA photo with transparency",
        lambda e: _image_mode(e, "rgba.png", lambda im: Image.fromarray(np.dstack([np.asarray(im), np.full((H, W), 128, np.uint8)]))),
        3,
        NO_OBJECTS,
        (r"rgba\.png has an alpha channel with transparent pixels; it is dropped",),
    ),
    # --- the depth map ---------------------------------------------------------------------
    Case("depth missing", lambda e: [e.photo, "--depth", str(e.inp / "nope.png")], 3, r"depth map not found: .*nope\.png"),
    Case("depth wrong size", lambda e: [e.photo, "--depth", str(_depth_png(e.inp / "small.png", MM[::4, ::4]))], 3, r"is 80x60 px but the image is 320x240 px; .*resize it to 320x240 with nearest-neighbour"),
    Case("depth colour image", lambda e: [e.photo, "--depth", (Image.fromarray(_photo()).save(e.inp / "c.png"), str(e.inp / "c.png"))[1]], 3, r"depth image .*c\.png has mode RGB; expected one channel"),
    Case("depth wrong dtype", lambda e: [e.photo, "--depth", _npy(e, "cplx.npy", MM.astype(np.complex64))], 3, r"depth array .*cplx\.npy has shape \(240, 320\) and dtype complex64; expected an \(H, W\) array"),
    Case("depth 8-bit", lambda e: [e.photo, "--depth", str(_depth_png(e.inp / "d8.png", MM / 40.0, np.uint8))], 3, r"d8\.png is an 8-bit image .*pass the 16-bit depth PNG, or --depth-scale METRES_PER_STEP"),
    Case("depth 8-bit with --depth-scale", lambda e: [*e.rgbd(), "--depth", str(_depth_png(e.inp / "d8.png", MM / 40.0, np.uint8)), "--depth-scale", "0.04"], 3, NO_OBJECTS),
    Case("depth all zero", lambda e: [e.photo, "--depth", str(_depth_png(e.inp / "zero.png", np.zeros((H, W))))], 3, r"has no valid depth \(all zero, NaN or negative\)"),
    Case("depth all NaN", lambda e: [e.photo, "--depth", _npy(e, "nan.npy", np.full((H, W), np.nan, np.float32))], 3, r"nan\.npy has no valid depth"),
    Case("depth negative", lambda e: [e.photo, "--depth", _npy(e, "neg.npy", -floor_depth_m().astype(np.float32) - 1.0)], 3, r"neg\.npy has no valid depth \(all zero, NaN or negative\)"),
    Case("depth too sparse", _sparse_depth, 3, r"measures only 0\.3% of the pixels \(need 5%\)"),
    Case("depth metres in a uint16 PNG", lambda e: [e.photo, "--depth", str(_depth_png(e.inp / "m.png", np.round(MM / 1000.0)))], 3, r"median depth 0\.00\d m when read as millimetres .*if the file stores metres, pass --depth-scale 1$"),
    Case("depth millimetres in a float array", lambda e: [e.photo, "--depth", _npy(e, "mm.npy", MM.astype(np.float32))], 3, r"median depth 3\d{3} m when read as metres \(a float file\).*if the file stores millimetres, pass --depth-scale 0\.001$"),
    Case("depth centimetres in a uint16 PNG", lambda e: [e.photo, "--depth", str(_depth_png(e.inp / "cm.png", np.round(MM / 10.0)))], 3, r"median depth 0\.3\d* m when read as millimetres .*no room's \(0\.4-15 m\); if the file stores centimetres, pass --depth-scale 0\.01$"),
    Case("depth 60 m away", lambda e: [e.photo, "--depth", str(_depth_png(e.inp / "far.png", np.full((H, W), 60000)))], 3, r"median depth 60 m .*which is no room's \(0\.4-15 m\); if the file stores tenths of a millimetre, pass --depth-scale 0\.0001$"),
    Case("depth scale zero", lambda e: [*e.rgbd(), "--depth-scale", "0"], 2, r"argument --depth-scale: expected a positive finite number, got '0'"),
    # --- intrinsics ------------------------------------------------------------------------
    Case("intrinsics not numbers", lambda e: [e.photo, "--intrinsics", "a,b,c,d"], 2, r"argument --intrinsics: expected fx,fy,cx,cy in pixels, got 'a,b,c,d'"),
    Case("intrinsics three numbers", lambda e: [e.photo, "--intrinsics", "260,260,160"], 2, r"expected 4 numbers fx,fy,cx,cy, got 3"),
    Case("intrinsics negative focal", lambda e: e.rgbd("--intrinsics=-260,260,160,120"), 3, r"--intrinsics: need finite fx, fy > 0"),
    Case("intrinsics zero focal", lambda e: e.rgbd("--intrinsics", "0,0,160,120"), 3, r"--intrinsics: need finite fx, fy > 0"),
    Case("intrinsics for another resolution", lambda e: e.rgbd("--intrinsics", "520,520,640,480"), 3, r"principal point \(640\.0, 480\.0\) px lies far outside the 320x240 image"),
    Case("intrinsics in millimetres", lambda e: e.rgbd("--intrinsics", "4.2,4.2,160,120"), 3, r"focal length 4\.2 px gives a 17\d degree field of view .*not millimetres"),
    Case("intrinsics fx fy mixed up", lambda e: e.rgbd("--intrinsics", "260,60,160,120"), 3, r"fx 260 px and fy 60 px differ more than 2x"),
    Case("field of view 200", lambda e: [e.photo, "--fov-deg", "200"], 2, r"argument --fov-deg: field of view must be between 1 and 175 degrees, got 200"),
    Case("both --intrinsics and --fov-deg", lambda e: [*e.rgbd(), "--fov-deg", "60"], 2, r"argument --fov-deg: not allowed with argument --intrinsics"),
    Case(
        "camera.json not JSON",
        lambda e: (_camera_json(e, "{fx: 1"), [e.photo, "--depth", e.depth])[1],
        3,
        r"cannot read intrinsics from .*camera\.json \(JSONDecodeError: .*\); it needs fx, fy, cx, cy, width, height",
    ),
    Case(
        "camera.json non-numeric",
        lambda e: (_camera_json(e, {"fx": "wide", "fy": 260, "cx": 160, "cy": 120}), [e.photo, "--depth", e.depth])[1],
        3,
        r"camera\.json: fx, fy, cx, cy must be numbers \(could not convert string to float: 'wide'\)",
    ),
    Case(
        "camera.json for another aspect ratio",
        lambda e: (_camera_json(e, {"fx": 260, "fy": 260, "cx": 160, "cy": 160, "width": 320, "height": 320}), [e.photo, "--depth", e.depth])[1],
        3,
        r"describes a 320x320 image but the photo is 320x240 \(different aspect ratio\); fix or remove it",
    ),
    Case(
        "--intrinsics and camera.json disagree",
        lambda e: (_camera_json(e, {"fx": 520, "fy": 520, "cx": 159.5, "cy": 119.5, "width": 320, "height": 240}), e.rgbd())[1],
        3,
        NO_OBJECTS,
        (r"--intrinsics \(fx 260\.0 px\) wins over .*camera\.json \(fx 520\.0 px\), which disagrees; drop one of them",),
    ),
    Case(
        "--fov-deg and camera.json disagree",
        lambda e: (_camera_json(e, {"fx": 260, "fy": 260, "cx": 159.5, "cy": 119.5}), [e.photo, "--depth", e.depth, "--fov-deg", "90"])[1],
        3,
        NO_OBJECTS,
        (r"--fov-deg 90 \(fx 160\.0 px\) wins over .*camera\.json \(fx 260\.0 px\), which disagrees",),
    ),
    # --- the output folder -----------------------------------------------------------------
    Case("output is a file", lambda e: (_write(e, "occupied", "x"), e.rgbd("-o", str(e.inp / "occupied")))[1], 3, r"output path .*occupied is a file; pass -o with a folder name"),
    Case("output is the current folder", lambda e: e.rgbd("-o", "."), 3, r"output folder \. is the current folder or contains it, and would be replaced"),
    Case("output contains the current folder", lambda e: e.rgbd("-o", ".."), 3, r"output folder \.\. is the current folder or contains it"),
    Case("output is the input's folder", lambda e: e.rgbd("-o", str(e.inp)), 3, r"output folder .* holds the input .*photo\.png and would be replaced; pass -o with a folder outside it"),
    Case("output inside the input's folder", lambda e: e.rgbd("-o", str(e.inp / "scene")), 3, r"output folder .*scene is inside the input's folder .*; pass -o with a folder outside it"),
    Case("output where no folder can be made", lambda e: e.rgbd("-o", "/proc/scene"), 3, r"cannot (write in /proc \(permission denied\)|create the output folder beside /proc/scene \(No such file or directory\)); choose another -o"),
    Case("output parent missing", lambda e: e.rgbd("-o", str(e.root / "no" / "such" / "out")), 3, r"output folder's parent .*such does not exist; create it or choose another -o"),
    Case("output holds the user's files", _user_folder, 3, r"output folder .*precious exists and was not written by scene-builder \(no \.scene-builder beside report\.json\); it is never replaced, even with --overwrite: choose another -o, or move it away yourself"),
    Case("output holds the user's files, --overwrite", _user_folder_overwrite, 3, r"output folder .*precious exists and was not written by scene-builder .*never replaced, even with --overwrite"),
    Case("output build folder with a file added", _output_with_user_file, 3, r"output folder .*out holds files added or changed since scene-builder wrote it \(added: notes\.txt\); move them, choose another -o, or pass --overwrite to replace the folder with them"),
    Case("output build folder with a file changed", _output_with_file_changed, 3, r"output folder .*out holds files added or changed since scene-builder wrote it \(changed: scene\.xml\)"),
    Case("default output holds another image's build", _default_name_taken, 3, r"photo_scene holds the build of another image \(.*other/photo\.png\); pass -o NAME \(e\.g\. -o in_photo_scene\) or --overwrite"),
    # --- the scene -------------------------------------------------------------------------
    Case("scene with no objects", lambda e: e.rgbd(), 3, NO_OBJECTS),
    # --- the command line ------------------------------------------------------------------
    Case("unknown flag", lambda e: [*e.rgbd(), "--colour"], 2, r"unrecognized arguments: --colour \(see 'scene-builder' --help\)|unrecognized arguments: --colour"),
    Case("no image", lambda e: ["build"], 2, r"the following arguments are required: image"),
    Case("infinite settle time", lambda e: [*e.rgbd(), "--settle-s", "inf"], 2, r"argument --settle-s: expected a positive finite number, got 'inf'"),
]


def _tree(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


@pytest.fixture()
def env(tmp_path: Path, monkeypatch) -> Env:
    inp, work = tmp_path / "in", tmp_path / "work"
    inp.mkdir()
    work.mkdir()
    Image.fromarray(_photo()).save(inp / "photo.png")
    _depth_png(inp / "depth.png", MM)
    monkeypatch.chdir(work)
    return Env(tmp_path, inp, work)


def run_case(case: Case, env: Env, capsys) -> tuple[int, list[str]]:
    argv = case.args(env)
    capsys.readouterr()
    before = _tree(env.root)
    try:
        code = main([*argv, "-q", "--viz", "off"] if argv and argv[0] != "build" else argv)
    except SystemExit as exc:  # argparse
        code = exc.code
    lines = capsys.readouterr().err.strip().splitlines()
    if case.error is not None:
        assert _tree(env.root) == before, f"{case.id}: a failed build left files behind"
    return code, lines


def test_catalogue_has_at_least_30_bad_inputs():
    assert len(CASES) >= 30
    assert len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input(case: Case, env: Env, capsys):
    code, lines = run_case(case, env, capsys)
    assert code == case.code, f"{case.id}: exit {code}, stderr {lines}"
    assert len(lines) == len(case.warnings) + 1, f"{case.id}: expected {len(case.warnings)} warning(s) and one error, got {lines}"
    for pattern, line in zip(case.warnings, lines):
        assert line.startswith("warning: ") and re.search(pattern, line), f"{case.id}: {line!r} does not match {pattern!r}"
    assert lines[-1].startswith("error: "), lines[-1]
    assert re.search(case.error, lines[-1]), f"{case.id}: {lines[-1]!r} does not match {case.error!r}"


def _without_root_privileges() -> None:
    """In a child about to exec: drop the capabilities that let root ignore file permissions
    (CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH) from the bounding set, so the exec'd program, still
    uid 0, is held to the folders' permission bits like any user."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    pr_capbset_drop, cap_dac_override, cap_dac_read_search = 24, 1, 2
    for cap in (cap_dac_override, cap_dac_read_search):
        if libc.prctl(pr_capbset_drop, cap, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP) failed")


def test_output_parent_read_only(env: Env):
    """A read-only parent folder: exit 3, one line, nothing written. The CLI runs in a child
    process; as root (CI), that child runs without the capabilities that override permissions."""
    import os
    import subprocess
    import sys

    from .conftest import REPO

    argv = [*_read_only_parent(env), "-q", "--viz", "off"]
    before = _tree(env.root)
    run = subprocess.run(
        [sys.executable, "-m", "scene_builder.cli", *argv],
        cwd=env.work,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        preexec_fn=_without_root_privileges if os.geteuid() == 0 else None,
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 3 and len(lines) == 1, run.stderr[-2000:]
    assert re.search(r"error: cannot write in .*readonly \(permission denied\); choose another -o", lines[0]), lines
    assert _tree(env.root) == before


def test_the_users_folder_survives_intact(env: Env, capsys):
    """The data-loss case of issue 12: `-o precious` where precious/ holds the user's file."""
    code, lines = run_case(next(c for c in CASES if c.id == "output holds the user's files"), env, capsys)
    assert code == 3
    assert (env.work / "precious" / "thesis.txt").read_text() == "four years of work"
    assert sorted(p.name for p in (env.work / "precious").iterdir()) == ["thesis.txt"]
