"""Loading and checking the user's input: the photo, an optional aligned depth map, intrinsics.

Everything that is wrong with the input raises :class:`scene_builder.errors.InputError` with one
line saying what is wrong and what to do. Only numpy and PIL are used (PIL is light to import).

Intrinsics are looked up in this order (``CameraIntrinsics.source`` says which answered):

1. ``InputSpec.intrinsics`` (``"flag"``), given for the image as stored on disk (after EXIF
   orientation);
2. ``camera.json`` next to the image (``"file"``): ``{"fx", "fy", "cx", "cy", "width",
   "height"}``, scaled when its size differs from the image's;
3. the EXIF focal length (``"exif"``): ``FocalLengthIn35mmFilm``, else ``FocalLength`` with the
   focal-plane resolution (sensor size);
4. ``InputSpec.fov_deg`` (``"flag"``) or ``PerceptionConfig.default_fov_deg`` (``"default-fov"``),
   horizontal field of view with a centred principal point.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scene_builder.config import InputSpec, PerceptionConfig
from scene_builder.errors import InputError
from scene_builder.model import CameraIntrinsics

__all__ = [
    "LoadedInput",
    "MAX_SIDE_PX",
    "MIN_VALID_DEPTH_FRACTION",
    "check_depth",
    "load_depth",
    "load_input",
    "load_rgb",
    "resolve_intrinsics",
]

#: Longest image side analysed; larger inputs are downscaled for perception (which does not need
#: more, and whose time then stays bounded for any photo size); the full-resolution photo is kept
#: as ``LoadedInput.rgb_full`` (and ``Observation.rgb_full``) for textures.
MAX_SIDE_PX = 1280
#: A depth map must measure at least this fraction of the pixels to be usable.
MIN_VALID_DEPTH_FRACTION = 0.05
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


def load_rgb(path: Path) -> tuple[np.ndarray, dict[int, object], tuple[int, int]]:
    """Read a photo as RGB with its EXIF orientation applied.

    Returns rgb (H, W, 3) uint8, the EXIF tags (main IFD merged with the Exif IFD) and the size
    (width, height) of the image as stored before the orientation was applied.
    """
    from PIL import Image, ImageOps, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise InputError(f"image not found: {path} (check the path)")
    try:
        with Image.open(path) as im:
            im.load()
            stored_size = im.size
            exif = im.getexif()
            tags: dict[int, object] = dict(exif)
            tags.update(exif.get_ifd(_EXIF_IFD))
            rgb_image = ImageOps.exif_transpose(im).convert("RGB")
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as err:
        raise InputError(f"cannot read {path} as an image ({err}); pass a JPEG or PNG photo") from err
    rgb = np.asarray(rgb_image, dtype=np.uint8)
    if rgb.shape[0] < 16 or rgb.shape[1] < 16:
        raise InputError(f"image {path} is only {rgb.shape[1]}x{rgb.shape[0]} px; pass a photo of at least 16x16 px")
    return rgb, tags, stored_size


def load_depth(path: Path, depth_scale: float) -> np.ndarray:
    """Read a depth map as (H, W) float32 metres with 0 where invalid.

    Integer images (8-, 16- or 32-bit single channel, e.g. a uint16 PNG in millimetres) are
    multiplied by ``depth_scale`` (metres per unit). Floating-point images (32-bit TIFF, mode
    ``F``) and ``.npy`` float arrays are metres already; integer ``.npy`` arrays are scaled like
    images. NaN, infinite and negative values are invalid (0).
    """
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not (np.isfinite(depth_scale) and depth_scale > 0):
        raise InputError(f"depth scale must be a positive number of metres per depth unit, got {depth_scale} (0.001 for millimetre PNGs)")
    if not path.is_file():
        raise InputError(f"depth map not found: {path} (check the path, or leave depth out to estimate it)")
    if path.suffix.lower() == ".npy":
        try:
            raw = np.load(path, allow_pickle=False)
        except (ValueError, OSError, EOFError) as err:
            raise InputError(f"cannot read {path} as a .npy depth array ({err}); save it with numpy.save") from err
        if raw.ndim == 3 and raw.shape[2] == 1:
            raw = raw[:, :, 0]
        if raw.ndim != 2 or not (np.issubdtype(raw.dtype, np.floating) or np.issubdtype(raw.dtype, np.integer)):
            raise InputError(f"depth array {path} has shape {raw.shape} and dtype {raw.dtype}; expected an (H, W) array of metres")
        is_float = np.issubdtype(raw.dtype, np.floating)
    else:
        try:
            with Image.open(path) as im:
                im.load()
                mode = im.mode
                if mode not in ("L", "I", "I;16", "I;16B", "I;16L", "F"):
                    raise InputError(
                        f"depth image {path} has mode {mode}; expected one channel (uint16 PNG in millimetres, 8/32-bit grey, or a float32 TIFF)"
                    )
                raw = np.asarray(im)
        except (UnidentifiedImageError, OSError, SyntaxError) as err:
            raise InputError(f"cannot read {path} as a depth image ({err}); pass a uint16 PNG or a .npy of metres") from err
        is_float = mode == "F"
    depth = raw.astype(np.float64)
    if not is_float:
        depth = depth * float(depth_scale)
    depth[~np.isfinite(depth) | (depth < 0.0)] = 0.0
    return depth.astype(np.float32)


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
    return k


def _make(fx, fy, cx, cy, width: int, height: int, source: str, what: str) -> CameraIntrinsics:
    try:
        values = [float(v) for v in (fx, fy, cx, cy)]
    except (TypeError, ValueError) as err:
        raise InputError(f"{what}: fx, fy, cx, cy must be numbers ({err})") from err
    if not all(math.isfinite(v) for v in values) or values[0] <= 0 or values[1] <= 0:
        raise InputError(f"{what}: need finite fx, fy > 0 and finite cx, cy in pixels, got {tuple(values)}")
    return _checked(CameraIntrinsics(*values, int(width), int(height), source), what)


def _from_camera_json(path: Path, width: int, height: int) -> CameraIntrinsics:
    try:
        data = json.loads(path.read_text())
        fx, fy, cx, cy = data["fx"], data["fy"], data["cx"], data["cy"]
        w, h = data.get("width", width), data.get("height", height)
        w, h = int(w), int(h)
    except (OSError, ValueError, TypeError, KeyError) as err:
        raise InputError(f"cannot read intrinsics from {path} ({type(err).__name__}: {err}); it needs fx, fy, cx, cy, width, height") from err
    if w <= 0 or h <= 0:
        raise InputError(f"{path}: width and height must be positive, got {w}x{h}")
    if abs(w / h - width / height) > 0.01 * (width / height):
        raise InputError(f"{path} describes a {w}x{h} image but the photo is {width}x{height} (different aspect ratio); fix or remove it")
    k = _make(fx, fy, cx, cy, w, h, "file", str(path))
    return k if (w, h) == (width, height) else k.scaled(width, height)


def _rational(value) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return v if math.isfinite(v) and v > 0 else None


def _from_exif(tags: dict[int, object], width: int, height: int, stored_size: tuple[int, int]) -> CameraIntrinsics | None:
    """Square-pixel intrinsics from EXIF focal length, or None when EXIF does not say."""
    f35 = _rational(tags.get(_TAG_FOCAL_35MM))
    if f35 is not None:
        # The 35 mm equivalent focal length is defined on the diagonal (CIPA DC-008).
        f_px = f35 * math.hypot(width, height) / _FULL_FRAME_DIAGONAL_MM
        return _checked(CameraIntrinsics(f_px, f_px, (width - 1) / 2.0, (height - 1) / 2.0, width, height, "exif"), "EXIF focal length")
    f_mm = _rational(tags.get(_TAG_FOCAL_LENGTH))
    x_res = _rational(tags.get(_TAG_FOCAL_PLANE_X_RES))
    unit_mm = _RES_UNIT_MM.get(int(tags.get(_TAG_FOCAL_PLANE_RES_UNIT, 2) or 2))
    if f_mm is None or x_res is None or unit_mm is None:
        return None
    # FocalPlaneXResolution is in pixels per unit of the sensor image (ExifImageWidth wide).
    # Both are before the orientation is applied; pixels are square so the rotation keeps f_px.
    exif_w = _rational(tags.get(_TAG_EXIF_IMAGE_WIDTH)) or float(stored_size[0])
    f_px = f_mm * x_res / unit_mm * (stored_size[0] / exif_w)
    return _checked(CameraIntrinsics(f_px, f_px, (width - 1) / 2.0, (height - 1) / 2.0, width, height, "exif"), "EXIF focal length")


def resolve_intrinsics(
    inputs: InputSpec,
    config: PerceptionConfig,
    width: int,
    height: int,
    exif: dict[int, object] | None = None,
    stored_size: tuple[int, int] | None = None,
) -> CameraIntrinsics:
    """Intrinsics of a ``width`` x ``height`` image, looked up in the order of the module doc."""
    if inputs.intrinsics is not None:
        if len(inputs.intrinsics) != 4:
            raise InputError(f"--intrinsics needs 4 numbers fx,fy,cx,cy in pixels, got {len(inputs.intrinsics)}")
        return _make(*inputs.intrinsics, width, height, "flag", "--intrinsics")
    camera_json = Path(inputs.image_path).with_name("camera.json")
    if camera_json.is_file():
        return _from_camera_json(camera_json, width, height)
    if exif:
        k = _from_exif(exif, width, height, stored_size or (width, height))
        if k is not None:
            return k
    fov, source = (inputs.fov_deg, "flag") if inputs.fov_deg is not None else (config.default_fov_deg, "default-fov")
    if not (fov is not None and math.isfinite(fov) and 1.0 <= fov <= 175.0):
        raise InputError(f"field of view must be between 1 and 175 degrees, got {fov}")
    return CameraIntrinsics.from_fov(width, height, float(fov), source)


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
    if inputs.depth_path is not None:
        depth = load_depth(Path(inputs.depth_path), inputs.depth_scale)
        if depth.shape != (h, w):
            same_aspect = abs(depth.shape[1] * h - depth.shape[0] * w) <= 0.01 * w * h / max(depth.shape)
            hint = (
                f"it has the photo's aspect ratio: if it covers the same field of view, resize it to {w}x{h} with nearest-neighbour first"
                if same_aspect
                else "pass a depth map registered to the photo at the same size"
            )
            raise InputError(f"depth map {inputs.depth_path} is {depth.shape[1]}x{depth.shape[0]} px but the image is {w}x{h} px; {hint}")
        check_depth(depth, f"depth map {inputs.depth_path}")
    k = resolve_intrinsics(inputs, config, w, h, exif, stored_size)
    full = rgb
    rgb, depth, k, scale = _downscale(rgb, depth, k)
    return LoadedInput(Path(inputs.image_path), rgb, depth, k, scale, None if scale == 1.0 else full)
