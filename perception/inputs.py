"""Loading and checking the user's input: the photo, an optional aligned depth map, intrinsics.

Everything that is wrong with the input raises :class:`scene_builder.errors.InputError` with one
line saying what is wrong and what to do. Only numpy and PIL are used (PIL is light to import).

Intrinsics are looked up in this order (``CameraIntrinsics.source`` says which answered); what
the user typed wins over what is found beside or inside the image, and when a lower source is
present and disagrees (focal length more than 5 % apart) an :class:`InputWarning` says which won:

1. ``InputSpec.intrinsics`` (``"flag"``), given for the image as displayed (after EXIF
   orientation);
2. ``InputSpec.fov_deg`` (``"flag"``), horizontal field of view with a centred principal point;
3. ``camera.json`` next to the image (``"file"``): ``{"fx", "fy", "cx", "cy", "width",
   "height"}``, scaled when its size differs from the image's;
4. the EXIF focal length (``"exif"``): ``FocalLengthIn35mmFilm``, else ``FocalLength`` with the
   focal-plane resolution (sensor size);
5. ``PerceptionConfig.default_fov_deg`` (``"default-fov"``).

Images: any mode PIL reads (grey, 16-bit grey, palette, CMYK, RGBA...) becomes 8-bit RGB; an alpha
channel with transparent pixels is dropped with a warning; images over :data:`MAX_IMAGE_PIXELS`
(including decompression bombs: a small file that declares a huge image) are refused before
their pixels are decoded.

Depth units (:func:`load_depth`): integer images are millimetres and float images / ``.npy``
arrays metres unless ``InputSpec.depth_scale`` says otherwise; 8-bit images are refused without an
explicit scale, and a depth map whose median is not that of a room (:data:`ROOM_MEDIAN_DEPTH_M`)
is refused with the scale that would make it one.
"""

from __future__ import annotations

import json
import math
import tokenize
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scene_builder.config import InputSpec, PerceptionConfig
from scene_builder.errors import PIL_READ_ERRORS, InputError, InputWarning
from scene_builder.model import CameraIntrinsics

__all__ = [
    "LoadedInput",
    "MAX_IMAGE_PIXELS",
    "MAX_SIDE_PX",
    "MIN_VALID_DEPTH_FRACTION",
    "ROOM_MEDIAN_DEPTH_M",
    "check_depth",
    "check_paths",
    "load_depth",
    "load_input",
    "load_rgb",
    "read_camera_json",
    "resolve_intrinsics",
]

#: Longest image side analysed; larger inputs are downscaled for perception (which does not need
#: more, and whose time then stays bounded for any photo size); the full-resolution photo is kept
#: as ``LoadedInput.rgb_full`` (and ``Observation.rgb_full``) for textures.
MAX_SIDE_PX = 1280
#: A depth map smaller than the photo with its aspect ratio and at least this many rows is
#: upsampled to it (ARKit's scene depth is 256x192); a smaller one is refused.
MIN_UPSAMPLED_DEPTH_PX = 96
#: ... bilinear where its 3x3 neighbourhood spans less than this share of the depth.
UPSAMPLE_SMOOTH = 0.03
#: Largest image (and depth map) read, in pixels: 100 MP is above any phone's default mode
#: (48-108 MP sensors); a larger file is refused from its header, before it is decoded.
MAX_IMAGE_PIXELS = 100_000_000
#: A depth map must measure at least this fraction of the pixels to be usable.
MIN_VALID_DEPTH_FRACTION = 0.05
#: The median of a room's measured depth lies in this range (metres) when the depth scale is
#: inferred from the file; with an explicit ``depth_scale`` the wider range
#: :data:`_EXPLICIT_MEDIAN_DEPTH_M` applies (the user said what the units are).
ROOM_MEDIAN_DEPTH_M = (0.4, 15.0)
_EXPLICIT_MEDIAN_DEPTH_M = (0.05, 100.0)
#: Depth nearer than this (metres) is taken as invalid: the sensors that capture rooms measure
#: from farther (Kinect v1 and v2 0.5 m, Azure Kinect 0.25 m, RealSense D435 about 0.2 m), so
#: such values are flying pixels and saturation artefacts (esanet_sample, a Kinect v2 frame: 322
#: pixels at 1-30 cm in a room 1.7-4 m deep, which became a 'bowl' 7 cm from the lens).
MIN_ROOM_DEPTH_M = 0.2
#: Focal lengths giving a horizontal field of view outside this range (degrees) are no camera's.
_FOV_RANGE_DEG = (2.0, 170.0)
#: fx / fy beyond this ratio (either way) is not a camera's pixel aspect.
_MAX_PIXEL_ASPECT = 2.0
#: Two intrinsics sources disagree when their focal lengths differ by more than this fraction.
_DISAGREE = 0.05
#: The principal point may lie at most this fraction of the image size outside the image.
_PRINCIPAL_POINT_MARGIN = 0.1

# EXIF tags (numbers from the EXIF 2.32 specification).
_EXIF_IFD = 0x8769
_TAG_FOCAL_LENGTH = 0x920A
_TAG_FOCAL_35MM = 0xA405
_TAG_FOCAL_PLANE_X_RES = 0xA20E
_TAG_FOCAL_PLANE_RES_UNIT = 0xA210
_TAG_EXIF_IMAGE_WIDTH = 0xA002
_RES_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}  # inch, cm, mm, micrometre
_FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)


@dataclass(frozen=True, eq=False)
class LoadedInput:
    """The checked input, downscaled so that its longest side is at most :data:`MAX_SIDE_PX`.

    rgb: (H, W, 3) uint8, EXIF orientation applied.
    depth_m: (H, W) float32 planar depth in metres, 0 where invalid; None without a depth map.
    intrinsics: for the (possibly downscaled) image.
    scale: factor applied to the stored image's size (1.0 when not downscaled).
    rgb_full: (H', W', 3) uint8 the photo at its stored resolution when it was downscaled, else None.
    """

    image_path: Path
    rgb: np.ndarray
    depth_m: np.ndarray | None
    intrinsics: CameraIntrinsics
    scale: float = 1.0
    rgb_full: np.ndarray | None = None
    #: (width, height) of the depth map as given when it was smaller than the photo with the
    #: same aspect ratio and was upsampled to it (a phone's LiDAR depth, 256x192 beside a
    #: 1920x1440 photo), else None.
    depth_upsampled_from: tuple[int, int] | None = None


def _open_checked(path: Path, what: str, hint: str):
    """Open ``path`` with PIL (header only), refusing images over :data:`MAX_IMAGE_PIXELS`.
    Returns the open image; the caller closes it."""
    from PIL import Image

    try:
        with warnings.catch_warnings():
            # PIL warns above 89 MP and raises above twice that; our own limit is checked below.
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            im = Image.open(path)
    except Image.DecompressionBombError as err:
        raise InputError(f"{what} {path} is too large to read ({err}); pass an image of at most {MAX_IMAGE_PIXELS // 1_000_000} MP") from err
    except PIL_ERRORS as err:
        raise InputError(f"cannot read {path} as {hint} ({_short(err)}); pass a JPEG or PNG file") from err
    w, h = im.size
    if w * h > MAX_IMAGE_PIXELS:
        im.close()
        raise InputError(
            f"{what} {path} is {w}x{h} px ({w * h / 1e6:.0f} MP); scene-builder reads images of at most "
            f"{MAX_IMAGE_PIXELS // 1_000_000} MP: downscale it first"
        )
    return im


#: What Pillow raises for a file it cannot read (:data:`scene_builder.errors.PIL_READ_ERRORS`).
#: Caught only around Pillow's own calls on the user's file (never around this module's code,
#: whose bugs must surface as themselves), and turned into one InputError line with the cause.
#: ``python -m scene_builder.bench.fuzz`` checks that nothing else escapes.
PIL_ERRORS = PIL_READ_ERRORS
#: What ``numpy.load`` raises for a malformed ``.npy`` file: OSError, ValueError and EOFError (its
#: documented ones: a header that is no dictionary of ``descr``, ``fortran_order``, ``shape`` is a
#: ValueError) and three it does not document, found by the fuzzer: ``tokenize.TokenError`` (its
#: header filter, on an unterminated bracket), SyntaxError (``ast.literal_eval`` of the header
#: text, 5 of 100,000 inputs) and OverflowError (``memmap`` of a shape beyond a C long, 7 of
#: 100,000). Caught only around numpy's reading of the file.
NPY_ERRORS: tuple[type[BaseException], ...] = (OSError, ValueError, EOFError, SyntaxError, OverflowError, tokenize.TokenError)


def _short(err: BaseException) -> str:
    """One line of an exception's message (PIL's can span lines)."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= 160 else text[:157] + "..."


@contextmanager
def _reading(path: Path, hint: str):
    """Around Pillow's calls on the user's file: :data:`PIL_ERRORS` become one InputError line."""
    try:
        yield
    except PIL_ERRORS as err:
        raise InputError(f"cannot read {path} as {hint} ({_short(err)}); pass a JPEG or PNG photo") from err


def _to_rgb(im, path: Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB of any PIL mode (``im`` loaded): 16/32-bit grey and float grey scaled
    to 8 bits, an alpha channel dropped (with a warning when some pixels are transparent)."""
    mode = im.mode
    if mode.startswith("I") or mode == "F":
        with _reading(path, "an image"):
            a = np.asarray(im)
        a = a.astype(np.float64)
        finite = a[np.isfinite(a)]
        top = float(finite.max()) if finite.size else 0.0
        scale = 1.0 if top <= 255.0 else (255.0 / 65535.0 if top <= 65535.0 else 255.0 / top)
        if mode == "F" and 0.0 < top <= 1.0:
            scale = 255.0
        grey = np.clip(np.nan_to_num(a * scale), 0.0, 255.0).round().astype(np.uint8)
        warnings.warn(
            f"{path} is a {mode} grey image (not a photo's 8-bit colour); read as grey. Is it a depth map? Pass it with --depth",
            InputWarning,
            stacklevel=3,
        )
        return np.repeat(grey[:, :, None], 3, axis=2)
    has_alpha = mode in ("RGBA", "LA", "PA", "La", "RGBa") or (mode == "P" and "transparency" in im.info)
    if has_alpha:
        with _reading(path, "an image"):
            rgba = np.asarray(im.convert("RGBA"))
        if (rgba[:, :, 3] < 255).any():
            warnings.warn(
                f"{path} has an alpha channel with transparent pixels; it is dropped (transparent pixels show their RGB values)",
                InputWarning,
                stacklevel=3,
            )
        return np.ascontiguousarray(rgba[:, :, :3])
    with _reading(path, "an image"):
        return np.asarray(im.convert("RGB"), dtype=np.uint8)


def check_paths(inputs: InputSpec) -> None:
    """Raise InputError (as :func:`load_rgb` / :func:`load_depth` would) when the image or the depth
    map is missing or a folder: a cheap check before anything else is looked at."""
    _check_path(Path(inputs.image_path), "image")
    if inputs.depth_path is not None:
        _check_path(Path(inputs.depth_path), "depth map")


def _check_path(path: Path, what: str) -> None:
    if path.is_dir():
        raise InputError(f"{what} {path} is a folder; pass the {'photo' if what == 'image' else 'depth'} file inside it")
    if not path.is_file():
        hint = "check the path" if what == "image" else "check the path, or leave depth out to estimate it"
        raise InputError(f"{what} not found: {path} ({hint})")


def load_rgb(path: Path) -> tuple[np.ndarray, dict[int, object], tuple[int, int]]:
    """Read a photo as RGB with its EXIF orientation applied.

    Returns rgb (H, W, 3) uint8, the EXIF tags (main IFD merged with the Exif IFD) and the size
    (width, height) of the image as stored before the orientation was applied.
    """
    path = Path(path)
    _check_path(path, "image")
    im = _open_checked(path, "image", "an image")
    with im:
        with _reading(path, "an image"):
            im.load()
        stored_size = im.size
        tags, oriented = _exif(im, path)
        rgb = _to_rgb(oriented, path)
    if rgb.shape[0] < 16 or rgb.shape[1] < 16:
        raise InputError(f"image {path} is only {rgb.shape[1]}x{rgb.shape[0]} px; pass a photo of at least 16x16 px")
    return rgb, tags, stored_size


def _exif(im, path: Path) -> tuple[dict[int, object], object]:
    """The EXIF tags of a loaded image (main IFD merged with the Exif IFD) and the image with its
    EXIF orientation applied; broken EXIF data is ignored with a warning (the photo is still
    good). Pillow parses EXIF as a TIFF directory: a malformed one raises :data:`PIL_ERRORS`."""
    from PIL import ImageOps

    try:
        exif = im.getexif()
        tags: dict[int, object] = dict(exif)
        tags.update(exif.get_ifd(_EXIF_IFD))
        return tags, ImageOps.exif_transpose(im)
    except PIL_ERRORS as err:
        warnings.warn(f"{path}: unreadable EXIF data ignored ({_short(err)}); orientation and focal length not read", InputWarning, stacklevel=3)
        return {}, im


def load_depth(path: Path, depth_scale: float | None = None) -> np.ndarray:
    """Read a depth map as (H, W) float32 metres with 0 where invalid.

    ``depth_scale`` is metres per unit of the file. None (the default) infers it: integer images
    (16- or 32-bit single channel, e.g. a uint16 PNG) and integer ``.npy`` arrays are millimetres,
    floating-point images (32-bit TIFF, mode ``F``) and float ``.npy`` arrays metres. NaN,
    infinite and negative values are invalid (0), and so are values nearer than
    :data:`MIN_ROOM_DEPTH_M` (with an :class:`InputWarning` saying how many).

    Raises InputError for an unreadable file, an 8-bit image without an explicit scale (8 bits
    hold 0-255 mm: such files are visualisations, not measurements), and a median depth outside
    :data:`ROOM_MEDIAN_DEPTH_M` (naming the ``--depth-scale`` that would make it a room's).
    """
    path = Path(path)
    explicit = depth_scale is not None
    if explicit and not (isinstance(depth_scale, (int, float)) and math.isfinite(depth_scale) and depth_scale > 0):
        raise InputError(f"depth scale must be a positive number of metres per depth unit, got {depth_scale} (0.001 for millimetre PNGs)")
    _check_path(path, "depth map")
    eight_bit = False
    if path.suffix.lower() == ".npy":
        try:
            # Memory-mapped first: a header declaring a huge shape must not allocate it.
            raw = np.load(path, allow_pickle=False, mmap_mode="r")
        except NPY_ERRORS as err:
            raise InputError(f"cannot read {path} as a .npy depth array ({_short(err)}); save it with numpy.save") from err
        if not isinstance(raw, np.ndarray):
            raise InputError(f"{path} holds no array; save the depth with numpy.save")
        if raw.ndim == 3 and raw.shape[2] == 1:
            raw = raw[:, :, 0]
        kind = raw.dtype.kind
        if raw.ndim != 2 or kind not in "fiu" or raw.dtype.itemsize > 8:
            raise InputError(f"depth array {path} has shape {raw.shape} and dtype {raw.dtype}; expected an (H, W) array of metres")
        if raw.size > MAX_IMAGE_PIXELS:
            raise InputError(f"depth array {path} is {raw.shape[1]}x{raw.shape[0]}; at most {MAX_IMAGE_PIXELS // 1_000_000} MP is read")
        try:
            raw = np.array(raw)
        except NPY_ERRORS as err:
            raise InputError(f"cannot read {path} as a .npy depth array ({_short(err)})") from err
        is_float = kind == "f"
        eight_bit = raw.dtype.itemsize == 1
    else:
        im = _open_checked(path, "depth map", "a depth image")
        with im:
            mode = im.mode
            if mode not in ("L", "I", "I;16", "I;16B", "I;16L", "I;16N", "F"):
                raise InputError(
                    f"depth image {path} has mode {mode}; expected one channel (uint16 PNG in millimetres, 32-bit grey, or a float32 TIFF)"
                )
            try:
                im.load()
                raw = np.asarray(im)
            except PIL_ERRORS as err:
                raise InputError(f"cannot read {path} as a depth image ({_short(err)}); pass a uint16 PNG or a .npy of metres") from err
        is_float = mode == "F"
        eight_bit = mode == "L"
    if eight_bit and not explicit:
        raise InputError(
            f"depth map {path} is an 8-bit image (values 0-255): it cannot hold a room's depth in millimetres and is most likely a "
            "visualisation; pass the 16-bit depth PNG, or --depth-scale METRES_PER_STEP if its values really are depth"
        )
    scale = float(depth_scale) if explicit else (1.0 if is_float else 0.001)
    with np.errstate(all="ignore"):
        depth = raw.astype(np.float64) * scale
    depth[~np.isfinite(depth) | (depth < 0.0)] = 0.0
    _check_depth_units(depth, path, scale, explicit, is_float)
    near = (depth > 0.0) & (depth < MIN_ROOM_DEPTH_M)
    if near.any():
        warnings.warn(f"{path}: {int(near.sum())} depth pixels nearer than {MIN_ROOM_DEPTH_M:g} m taken as invalid "
                      "(no room-scale depth sensor measures there: artefacts)", InputWarning, stacklevel=2)
        depth[near] = 0.0
    return depth.astype(np.float32)


def _check_depth_units(depth_m: np.ndarray, path: Path, scale: float, explicit: bool, is_float: bool) -> None:
    """Refuse depth whose median is no room's, naming the scale that would make it one."""
    valid = depth_m[depth_m > 0.0]
    if valid.size == 0:
        return  # check_depth says "no valid depth"
    median = float(np.median(valid))
    lo, hi = _EXPLICIT_MEDIAN_DEPTH_M if explicit else ROOM_MEDIAN_DEPTH_M
    if lo <= median <= hi:
        return
    raw_median = median / scale
    fits = [s for s in (1.0, 0.1, 0.01, 0.001, 0.0001, 1e-5) if ROOM_MEDIAN_DEPTH_M[0] <= raw_median * s <= ROOM_MEDIAN_DEPTH_M[1]]
    unit = {1.0: "metres", 0.1: "decimetres", 0.01: "centimetres", 0.001: "millimetres", 0.0001: "tenths of a millimetre"}
    read_as = f"--depth-scale {scale:g}" if explicit else ("metres (a float file)" if is_float else "millimetres (an integer file)")
    what = f"depth map {path}: median depth {median:.4g} m when read as {read_as}, which is no room's ({ROOM_MEDIAN_DEPTH_M[0]:g}-{ROOM_MEDIAN_DEPTH_M[1]:g} m)"
    if fits:
        best = min(fits, key=lambda s: abs(math.log(raw_median * s / 2.5)))
        raise InputError(f"{what}; if the file stores {unit.get(best, f'units of {best:g} m')}, pass --depth-scale {best:g}")
    raise InputError(f"{what}; check the file, or pass --depth-scale with its metres per unit")


def check_depth(depth_m: np.ndarray, what: str) -> None:
    """Raise InputError when a depth map is unusable: all invalid, or fewer than 5 % measured."""
    valid = depth_m > 0.0
    if not valid.any():
        raise InputError(f"{what} has no valid depth (all zero, NaN or negative); check the file and --depth-scale")
    frac = float(valid.mean())
    if frac < MIN_VALID_DEPTH_FRACTION:
        raise InputError(
            f"{what} measures only {100 * frac:.1f}% of the pixels (need {100 * MIN_VALID_DEPTH_FRACTION:.0f}%); "
            "pass a denser depth map or leave depth out to estimate it"
        )


def _checked(k: CameraIntrinsics, what: str) -> CameraIntrinsics:
    mx, my = _PRINCIPAL_POINT_MARGIN * k.width_px, _PRINCIPAL_POINT_MARGIN * k.height_px
    if not (-mx <= k.cx_px <= k.width_px - 1 + mx and -my <= k.cy_px <= k.height_px - 1 + my):
        raise InputError(
            f"{what}: principal point ({k.cx_px:.1f}, {k.cy_px:.1f}) px lies far outside the "
            f"{k.width_px}x{k.height_px} image; were the intrinsics given for another resolution?"
        )
    fov = math.degrees(2.0 * math.atan(k.width_px / (2.0 * k.fx_px)))
    if not _FOV_RANGE_DEG[0] <= fov <= _FOV_RANGE_DEG[1]:
        raise InputError(
            f"{what}: focal length {k.fx_px:.4g} px gives a {fov:.3g} degree field of view over {k.width_px} px, which no camera has; "
            "give fx, fy in pixels of this image (not millimetres, not another resolution)"
        )
    if not 1.0 / _MAX_PIXEL_ASPECT <= k.fx_px / k.fy_px <= _MAX_PIXEL_ASPECT:
        raise InputError(f"{what}: fx {k.fx_px:.4g} px and fy {k.fy_px:.4g} px differ more than {_MAX_PIXEL_ASPECT:g}x; give fx,fy,cx,cy in that order")
    return k


def _make(fx, fy, cx, cy, width: int, height: int, source: str, what: str) -> CameraIntrinsics:
    values = []
    for v in (fx, fy, cx, cy):
        if isinstance(v, bool) or not isinstance(v, (int, float, str)):
            raise InputError(f"{what}: fx, fy, cx, cy must be numbers, got {type(v).__name__} {str(v)[:30]!r}")
        try:
            values.append(float(v))
        except (TypeError, ValueError, OverflowError) as err:
            raise InputError(f"{what}: fx, fy, cx, cy must be numbers ({_short(err)})") from err
    if not all(math.isfinite(v) for v in values) or values[0] <= 0 or values[1] <= 0:
        raise InputError(f"{what}: need finite fx, fy > 0 and finite cx, cy in pixels, got {tuple(values)}")
    return _checked(CameraIntrinsics(*values, int(width), int(height), source), what)


#: Largest width / height a camera.json may give (a 100 MP image is 12,000 px wide).
_MAX_JSON_SIDE = 1_000_000


def read_camera_json(path: Path, width: int, height: int) -> CameraIntrinsics:
    """Intrinsics of a ``width`` x ``height`` image from a ``camera.json`` (``fx, fy, cx, cy`` and
    optionally the ``width, height`` they were given for: then scaled). Raises InputError (one line)
    for anything else."""
    try:
        data = json.loads(path.read_text())
        if not isinstance(data, dict):
            raise TypeError(f"top level is a {type(data).__name__}, not an object")
        fx, fy, cx, cy = data["fx"], data["fy"], data["cx"], data["cy"]
        w, h = data.get("width", width), data.get("height", height)
        if isinstance(w, bool) or isinstance(h, bool) or not isinstance(w, (int, float)) or not isinstance(h, (int, float)):
            raise TypeError(f"width and height must be numbers, got {str(w)[:20]!r} and {str(h)[:20]!r}")
        if not all(isinstance(v, int) or math.isfinite(v) for v in (w, h)):
            raise ValueError(f"width and height must be finite, got {w} and {h}")
        w, h = int(w), int(h)
        if not (0 < w <= _MAX_JSON_SIDE and 0 < h <= _MAX_JSON_SIDE):
            raise ValueError(f"width and height must be 1..{_MAX_JSON_SIDE} px, got {w}x{h}")
    except (OSError, ValueError, TypeError, KeyError, RecursionError, OverflowError) as err:
        raise InputError(f"cannot read intrinsics from {path} ({type(err).__name__}: {_short(err)}); it needs fx, fy, cx, cy, width, height") from err
    if abs(w / h - width / height) > 0.01 * (width / height):
        raise InputError(f"{path} describes a {w}x{h} image but the photo is {width}x{height} (different aspect ratio); fix or remove it")
    k = _make(fx, fy, cx, cy, w, h, "file", str(path))
    return k if (w, h) == (width, height) else k.scaled(width, height)


def _rational(value) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        return None
    return v if math.isfinite(v) and v > 0 else None


def _from_exif(tags: dict[int, object], width: int, height: int, stored_size: tuple[int, int]) -> CameraIntrinsics | None:
    """Square-pixel intrinsics from EXIF focal length, or None when EXIF does not say (or says
    something no camera has: then a warning, and the next source answers)."""
    try:
        return _from_exif_tags(tags, width, height, stored_size)
    except InputError as err:
        warnings.warn(f"EXIF focal length ignored: {err}", InputWarning, stacklevel=3)
        return None


def _from_exif_tags(tags: dict[int, object], width: int, height: int, stored_size: tuple[int, int]) -> CameraIntrinsics | None:
    f35 = _rational(tags.get(_TAG_FOCAL_35MM))
    if f35 is not None:
        # The 35 mm equivalent focal length is defined on the diagonal (CIPA DC-008).
        f_px = f35 * math.hypot(width, height) / _FULL_FRAME_DIAGONAL_MM
        return _checked(CameraIntrinsics(f_px, f_px, (width - 1) / 2.0, (height - 1) / 2.0, width, height, "exif"), "EXIF focal length")
    f_mm = _rational(tags.get(_TAG_FOCAL_LENGTH))
    x_res = _rational(tags.get(_TAG_FOCAL_PLANE_X_RES))
    unit_mm = _RES_UNIT_MM.get(int(_rational(tags.get(_TAG_FOCAL_PLANE_RES_UNIT)) or 2))
    if f_mm is None or x_res is None or unit_mm is None:
        return None
    # FocalPlaneXResolution is in pixels per unit of the sensor image (ExifImageWidth wide).
    # Both are before the orientation is applied; pixels are square so the rotation keeps f_px.
    exif_w = _rational(tags.get(_TAG_EXIF_IMAGE_WIDTH)) or float(stored_size[0])
    f_px = f_mm * x_res / unit_mm * (stored_size[0] / exif_w)
    return _checked(CameraIntrinsics(f_px, f_px, (width - 1) / 2.0, (height - 1) / 2.0, width, height, "exif"), "EXIF focal length")


def _fov_intrinsics(fov, width: int, height: int, source: str, what: str) -> CameraIntrinsics:
    if not (isinstance(fov, (int, float)) and math.isfinite(fov) and 1.0 <= fov <= 175.0):
        raise InputError(f"{what}: field of view must be between 1 and 175 degrees, got {fov}")
    return CameraIntrinsics.from_fov(width, height, float(fov), source)


def resolve_intrinsics(
    inputs: InputSpec,
    config: PerceptionConfig,
    width: int,
    height: int,
    exif: dict[int, object] | None = None,
    stored_size: tuple[int, int] | None = None,
) -> CameraIntrinsics:
    """Intrinsics of a ``width`` x ``height`` image, looked up in the order of the module doc;
    warns (:class:`InputWarning`) when a lower source is present and disagrees with the winner."""
    chosen: tuple[CameraIntrinsics, str] | None = None
    if inputs.intrinsics is not None:
        if len(inputs.intrinsics) != 4:
            raise InputError(f"--intrinsics needs 4 numbers fx,fy,cx,cy in pixels, got {len(inputs.intrinsics)}")
        chosen = (_make(*inputs.intrinsics, width, height, "flag", "--intrinsics"), "--intrinsics")
    elif inputs.fov_deg is not None:
        chosen = (_fov_intrinsics(inputs.fov_deg, width, height, "flag", "--fov-deg"), f"--fov-deg {inputs.fov_deg:g}")
    camera_json = Path(inputs.image_path).with_name("camera.json")
    found: list[tuple[CameraIntrinsics, str]] = []
    if camera_json.is_file():
        if chosen is None:
            return read_camera_json(camera_json, width, height)
        try:
            found.append((read_camera_json(camera_json, width, height), f"{camera_json}"))
        except InputError as err:
            warnings.warn(f"{chosen[1]} is used; {camera_json} beside the image is ignored ({err})", InputWarning, stacklevel=2)
    if exif:
        k = _from_exif(exif, width, height, stored_size or (width, height))
        if k is not None:
            if chosen is None:
                return k
            found.append((k, "the EXIF focal length"))
    if chosen is None:
        return _fov_intrinsics(config.default_fov_deg, width, height, "default-fov", "default field of view")
    k, name = chosen
    for other, other_name in found[:1]:  # the next source in line is the one the flag overrides
        if abs(other.fx_px / k.fx_px - 1.0) > _DISAGREE or abs(other.cx_px - k.cx_px) > _DISAGREE * width:
            warnings.warn(
                f"{name} (fx {k.fx_px:.1f} px) wins over {other_name} (fx {other.fx_px:.1f} px), which disagrees; drop one of them to silence this",
                InputWarning,
                stacklevel=2,
            )
    return k


def _downscale(rgb: np.ndarray, depth_m: np.ndarray | None, k: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray | None, CameraIntrinsics, float]:
    from PIL import Image

    h, w = rgb.shape[:2]
    s = MAX_SIDE_PX / max(h, w)
    if s >= 1.0:
        return rgb, depth_m, k, 1.0
    nw, nh = max(1, round(w * s)), max(1, round(h * s))
    rgb_s = np.asarray(Image.fromarray(rgb).resize((nw, nh), Image.Resampling.LANCZOS, reducing_gap=2.0), dtype=np.uint8)
    depth_s = None
    if depth_m is not None:
        # Nearest neighbour: averaging depth across an edge would invent points in mid-air.
        depth_s = np.asarray(Image.fromarray(depth_m, mode="F").resize((nw, nh), Image.Resampling.NEAREST), dtype=np.float32)
    return rgb_s, depth_s, k.scaled(nw, nh), s


def load_input(inputs: InputSpec, config: PerceptionConfig) -> LoadedInput:
    """Load and check everything in ``inputs``; see the module doc for the intrinsics order."""
    rgb, exif, stored_size = load_rgb(Path(inputs.image_path))
    h, w = rgb.shape[:2]
    depth = None
    upsampled_from = None
    if inputs.depth_path is not None:
        depth = load_depth(Path(inputs.depth_path), inputs.depth_scale)
        if depth.shape != (h, w):
            same_aspect = abs(depth.shape[1] * h - depth.shape[0] * w) <= 0.01 * w * h / max(depth.shape)
            if (depth.shape[1], depth.shape[0]) == tuple(stored_size) and (w, h) != tuple(stored_size):
                hint = "it matches the image as stored, before its EXIF orientation is applied: rotate the depth map the same way"
            elif same_aspect and depth.shape[0] < h and depth.shape[0] >= MIN_UPSAMPLED_DEPTH_PX:
                hint = ""
            elif same_aspect:
                hint = f"it has the photo's aspect ratio: if it covers the same field of view, resize it to {w}x{h} with nearest-neighbour first"
            else:
                hint = "pass a depth map registered to the photo at the same size"
            if hint:
                raise InputError(f"depth map {inputs.depth_path} is {depth.shape[1]}x{depth.shape[0]} px but the image is {w}x{h} px; {hint}")
            depth, upsampled_from = _upsample_depth(depth, w, h), (depth.shape[1], depth.shape[0])
            warnings.warn(
                f"depth map {inputs.depth_path} is {upsampled_from[0]}x{upsampled_from[1]} px beside a {w}x{h} px photo of the same aspect ratio: "
                "taken to cover the same field of view (a phone's LiDAR depth does) and upsampled to it; pass a registered full-size map if it does not",
                InputWarning,
                stacklevel=2,
            )
        check_depth(depth, f"depth map {inputs.depth_path}")
    k = resolve_intrinsics(inputs, config, w, h, exif, stored_size)
    full = rgb
    rgb, depth, k, scale = _downscale(rgb, depth, k)
    return LoadedInput(Path(inputs.image_path), rgb, depth, k, scale, None if scale == 1.0 else full, upsampled_from)


#: A photo's frame: its outermost lines of one flat extreme colour (undistorted Kinect and NYU
#: frames are padded with 5-8 px of white; exports and scans pad black), at most this share of
#: the side. A line is frame when FRAME_LINE_SHARE of its pixels are all channels >= FRAME_BRIGHT
#: or all <= FRAME_DARK; the first line inside a frame is the resampling's blend and goes too.
MAX_FRAME_SHARE = 0.03
FRAME_LINE_SHARE = 0.9
FRAME_BRIGHT = 235
FRAME_DARK = 20


def photo_frame(rgb: np.ndarray) -> tuple[int, int, int, int]:
    """(top, bottom, left, right) widths in pixels of a flat frame around ``rgb`` (H, W, 3)
    uint8 (0 where there is none)."""
    h, w = rgb.shape[:2]

    def flat(line: np.ndarray) -> bool:
        return bool(np.mean(np.all(line >= FRAME_BRIGHT, axis=-1)) >= FRAME_LINE_SHARE or np.mean(np.all(line <= FRAME_DARK, axis=-1)) >= FRAME_LINE_SHARE)

    def width(lines, cap: int) -> int:
        n = 0
        while n < cap and flat(lines(n)):
            n += 1
        return min(n + 1, cap) if n else 0

    cap_v, cap_h = max(1, int(MAX_FRAME_SHARE * h)), max(1, int(MAX_FRAME_SHARE * w))
    return (width(lambda i: rgb[i], cap_v), width(lambda i: rgb[h - 1 - i], cap_v),
            width(lambda i: rgb[:, i], cap_h), width(lambda i: rgb[:, w - 1 - i], cap_h))


def without_frame(rgb: np.ndarray, frame: tuple[int, int, int, int]) -> np.ndarray:
    """``rgb`` with its frame (:func:`photo_frame`) replaced by the nearest pixels inside it (a
    twin seen from elsewhere shows the photo's texture on the room, not a white line along the
    photo's border). A new array; ``rgb`` itself when there is no frame."""
    top, bottom, left, right = frame
    if not any(frame):
        return rgb
    h, w = rgb.shape[:2]
    inner = rgb[top : h - bottom, left : w - right]
    return np.pad(inner, ((top, bottom), (left, right), (0, 0)), mode="edge")


def _upsample_depth(depth_m: np.ndarray, w: int, h: int) -> np.ndarray:
    """``depth_m`` (h', w') float32 resized to (h, w): bilinear where the input is smooth (its
    3x3 neighbourhood spans under :data:`UPSAMPLE_SMOOTH` of the depth and holds no invalid
    pixel: floors and walls without 7.5-pixel stairs), nearest neighbour elsewhere. Interpolating
    across a depth edge would invent points in mid-air between an object and the wall behind
    it; invalid zeros stay invalid. (OpenCV's resize does both; its edge-aware joint filters
    are in the contrib build, which the project does not install.)"""
    import cv2
    from scipy.ndimage import maximum_filter, minimum_filter

    d = np.ascontiguousarray(depth_m, dtype=np.float32)
    near = cv2.resize(d, (w, h), interpolation=cv2.INTER_NEAREST)
    lin = cv2.resize(d, (w, h), interpolation=cv2.INTER_LINEAR)
    hi, lo = maximum_filter(d, size=3, mode="nearest"), minimum_filter(d, size=3, mode="nearest")
    smooth = (lo > 0) & (hi - lo <= UPSAMPLE_SMOOTH * lo)
    smooth_up = cv2.resize(smooth.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST).astype(bool)
    return np.where(smooth_up, lin, near).astype(np.float32)
