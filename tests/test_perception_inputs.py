"""Perception input loading: every bad input class raises InputError with a useful line, and
intrinsics come from the flag, camera.json, EXIF or the default field of view."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
from PIL import Image

from perception.inputs import MAX_SIDE_PX, load_input
from scene_builder.config import InputSpec, PerceptionConfig
from scene_builder.errors import InputError, InputWarning

CFG = PerceptionConfig()


def _photo(path, w=64, h=48, exif=None):
    rng = np.random.default_rng(0)
    im = Image.fromarray(rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
    if exif is None:
        im.save(path)
    else:
        im.save(path, exif=exif)
    return path


def _depth_png(path, depth_mm):
    Image.fromarray(np.asarray(depth_mm, dtype=np.uint16)).save(path)
    return path


def _ramp_mm(w=64, h=48):
    return np.tile(np.linspace(1000, 3000, w), (h, 1)).astype(np.uint16)


# ------------------------------------------------------------------------------------------
# Bad inputs
# ------------------------------------------------------------------------------------------


def test_missing_image(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_input(InputSpec(tmp_path / "nope.jpg"), CFG)


def test_text_file_named_jpg(tmp_path):
    p = tmp_path / "photo.jpg"
    p.write_text("this is not a photo")
    with pytest.raises(InputError, match="cannot read .* as an image"):
        load_input(InputSpec(p), CFG)


def test_missing_depth(tmp_path):
    with pytest.raises(InputError, match="depth map not found"):
        load_input(InputSpec(_photo(tmp_path / "a.png"), tmp_path / "d.png"), CFG)


def test_corrupt_depth(tmp_path):
    d = tmp_path / "d.png"
    d.write_bytes(b"\x89PNG garbage")
    with pytest.raises(InputError, match="cannot read .* as a depth image"):
        load_input(InputSpec(_photo(tmp_path / "a.png"), d), CFG)


def test_rgb_depth_image_is_rejected(tmp_path):
    d = tmp_path / "d.png"
    _photo(d)
    with pytest.raises(InputError, match="one channel"):
        load_input(InputSpec(_photo(tmp_path / "a.png"), d), CFG)


def test_depth_of_wrong_size_names_both_sizes(tmp_path):
    d = _depth_png(tmp_path / "d.png", _ramp_mm(32, 24))
    with pytest.raises(InputError) as err:
        load_input(InputSpec(_photo(tmp_path / "a.png", 64, 48), d), CFG)
    assert "32x24" in str(err.value) and "64x48" in str(err.value)
    assert "resize it to 64x48" in str(err.value)  # same aspect ratio: say how to fix it
    d2 = _depth_png(tmp_path / "d2.png", _ramp_mm(48, 48))
    with pytest.raises(InputError, match="48x48 px but the image is 64x48 px; pass a depth map registered"):
        load_input(InputSpec(tmp_path / "a.png", d2), CFG)


def test_smaller_depth_of_the_photos_aspect_is_upsampled_sharp_at_edges(tmp_path):
    """A phone's LiDAR depth (ARKit: 256x192 beside a 1920x1440 photo) covers the photo's field of
    view at a lower resolution: it is upsampled, with a warning and the report saying so, smooth
    surfaces interpolated and a depth edge kept sharp (no points in mid-air between a box and
    the wall behind it)."""
    lw, lh = 120, 96
    low = np.tile(np.linspace(2000, 2600, lw), (lh, 1))  # a wall turning away: smooth
    low[30:60, 40:80] = 1000  # a box 1 m in front of it
    d = _depth_png(tmp_path / "d.png", low)
    with pytest.warns(InputWarning, match=r"120x96 px beside a 240x192 px photo of the same aspect ratio: .*upsampled"):
        loaded = load_input(InputSpec(_photo(tmp_path / "a.png", 240, 192), d), CFG)
    assert loaded.depth_m.shape == (192, 240)
    assert loaded.depth_upsampled_from == (120, 96)
    box = loaded.depth_m[60:120, 80:160]
    assert np.allclose(box, 1.0)
    # Across the box's edge every pixel is the box's or the wall's, none in between.
    edge = loaded.depth_m[50:130, 70:170]
    assert np.all((np.abs(edge - 1.0) < 1e-6) | (edge > 1.9))
    # On the wall, more distinct depths than the source's columns: interpolated, not stairs.
    row = loaded.depth_m[10]
    assert len(np.unique(np.round(row, 5))) > 1.5 * lw
    assert np.all(np.diff(row) >= -1e-6)
    # Too small to be a registered map at all: refused.
    d3 = _depth_png(tmp_path / "d3.png", _ramp_mm(30, 24))
    with pytest.raises(InputError, match="resize it to 240x192"):
        load_input(InputSpec(tmp_path / "a.png", d3), CFG)


def test_all_zero_depth(tmp_path):
    d = _depth_png(tmp_path / "d.png", np.zeros((48, 64)))
    with pytest.raises(InputError, match="no valid depth"):
        load_input(InputSpec(_photo(tmp_path / "a.png"), d), CFG)


def test_nan_depth_npy(tmp_path):
    d = tmp_path / "d.npy"
    np.save(d, np.full((48, 64), np.nan, dtype=np.float32))
    with pytest.raises(InputError, match="no valid depth"):
        load_input(InputSpec(_photo(tmp_path / "a.png"), d), CFG)


def test_too_little_valid_depth(tmp_path):
    depth = np.zeros((48, 64), dtype=np.float32)
    depth[:2, :50] = 2.0  # 100 of 3072 pixels: 3 %
    depth[5, 5] = np.inf
    depth[6, 6] = -1.0
    d = tmp_path / "d.npy"
    np.save(d, depth)
    with pytest.raises(InputError, match=r"only 3\.3% of the pixels"):
        load_input(InputSpec(_photo(tmp_path / "a.png"), d), CFG)


@pytest.mark.parametrize("scale", [0.0, -0.001, float("nan")])
def test_bad_depth_scale(tmp_path, scale):
    d = _depth_png(tmp_path / "d.png", _ramp_mm())
    with pytest.raises(InputError, match="depth scale must be a positive"):
        load_input(InputSpec(_photo(tmp_path / "a.png"), d, depth_scale=scale), CFG)


@pytest.mark.parametrize(
    "k, message",
    [
        ((-500.0, 500.0, 32.0, 24.0), "fx, fy > 0"),
        ((500.0, float("nan"), 32.0, 24.0), "fx, fy > 0"),
        ((500.0, 500.0, 320.0, 24.0), "principal point .* far outside"),
        ((500.0, 500.0, 32.0, -40.0), "principal point .* far outside"),
        ((500.0, 500.0, 32.0), "4 numbers"),
    ],
)
def test_bad_intrinsics_flag(tmp_path, k, message):
    with pytest.raises(InputError, match=message):
        load_input(InputSpec(_photo(tmp_path / "a.png"), intrinsics=k), CFG)


def test_unreadable_camera_json(tmp_path):
    img = _photo(tmp_path / "rgb.png")
    (tmp_path / "camera.json").write_text("{fx: 1")
    with pytest.raises(InputError, match="cannot read intrinsics from .*camera.json"):
        load_input(InputSpec(img), CFG)


def test_camera_json_for_another_aspect_ratio(tmp_path):
    img = _photo(tmp_path / "rgb.png", 64, 48)
    (tmp_path / "camera.json").write_text(json.dumps({"fx": 50, "fy": 50, "cx": 32, "cy": 32, "width": 64, "height": 64}))
    with pytest.raises(InputError, match="different aspect ratio"):
        load_input(InputSpec(img), CFG)


def test_bad_fov(tmp_path):
    with pytest.raises(InputError, match="field of view"):
        load_input(InputSpec(_photo(tmp_path / "a.png"), fov_deg=0.0), CFG)


# ------------------------------------------------------------------------------------------
# Intrinsics sources
# ------------------------------------------------------------------------------------------


def test_intrinsics_flag(tmp_path):
    k = load_input(InputSpec(_photo(tmp_path / "a.png"), intrinsics=(60.0, 61.0, 31.0, 23.0)), CFG).intrinsics
    assert k.source == "flag" and (k.fx_px, k.fy_px, k.cx_px, k.cy_px) == (60.0, 61.0, 31.0, 23.0)


def test_intrinsics_from_camera_json_scaled(tmp_path):
    img = _photo(tmp_path / "rgb.png", 64, 48)
    # camera.json written for the full-resolution 128x96 original of this photo.
    (tmp_path / "camera.json").write_text(json.dumps({"fx": 100.0, "fy": 102.0, "cx": 63.5, "cy": 47.5, "width": 128, "height": 96}))
    k = load_input(InputSpec(img), CFG).intrinsics
    assert k.source == "file"
    assert (k.fx_px, k.fy_px) == pytest.approx((50.0, 51.0))
    assert (k.cx_px, k.cy_px) == pytest.approx((31.5, 23.5))  # still the image centre


def test_intrinsics_flag_beats_camera_json(tmp_path):
    img = _photo(tmp_path / "rgb.png")
    (tmp_path / "camera.json").write_text(json.dumps({"fx": 100.0, "fy": 100.0, "cx": 32, "cy": 24, "width": 64, "height": 48}))
    with pytest.warns(InputWarning, match=r"--intrinsics \(fx 70\.0 px\) wins over .*camera\.json \(fx 100\.0 px\)"):
        assert load_input(InputSpec(img, intrinsics=(70.0, 70.0, 32.0, 24.0)), CFG).intrinsics.source == "flag"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # agreeing sources: no warning
        assert load_input(InputSpec(img, intrinsics=(100.0, 100.0, 32.0, 24.0)), CFG).intrinsics.fx_px == 100.0


def test_fov_flag_beats_camera_json_and_exif(tmp_path):
    img = _photo(tmp_path / "rgb.png")
    (tmp_path / "camera.json").write_text(json.dumps({"fx": 100.0, "fy": 100.0, "cx": 31.5, "cy": 23.5}))
    with pytest.warns(InputWarning, match="--fov-deg 90 .* wins over"):
        k = load_input(InputSpec(img, fov_deg=90.0), CFG).intrinsics
    assert k.source == "flag" and k.fx_px == pytest.approx(32.0)
    exif = Image.Exif()
    exif.get_ifd(0x8769)[0xA405] = 28
    jpg = _photo(tmp_path / "sub.jpg", 60, 40, exif=exif)
    (tmp_path / "camera.json").unlink()
    with pytest.warns(InputWarning, match="wins over the EXIF focal length"):
        assert load_input(InputSpec(jpg, fov_deg=90.0), CFG).intrinsics.source == "flag"


# ------------------------------------------------------------------------------------------
# Image modes and depth units
# ------------------------------------------------------------------------------------------


def test_image_modes_become_rgb(tmp_path):
    from perception.inputs import load_rgb

    rgb = np.asarray(Image.open(_photo(tmp_path / "a.png")))
    grey = np.asarray(Image.fromarray(rgb).convert("L"))
    Image.fromarray(grey.astype(np.uint16) * 257).save(tmp_path / "g16.png")
    with pytest.warns(InputWarning, match="grey image"):
        out, _, _ = load_rgb(tmp_path / "g16.png")
    np.testing.assert_array_equal(out[:, :, 0], grey)  # 16 bits scaled back to 8, not clipped at 255
    Image.fromarray(np.dstack([rgb, np.full(rgb.shape[:2], 255, np.uint8)])).save(tmp_path / "opaque.png")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # fully opaque alpha: nothing to say
        np.testing.assert_array_equal(load_rgb(tmp_path / "opaque.png")[0], rgb)
    Image.fromarray(rgb).convert("CMYK").save(tmp_path / "cmyk.jpg", quality=95)
    assert load_rgb(tmp_path / "cmyk.jpg")[0].shape == rgb.shape


def test_explicit_depth_scale_applies_to_float_files(tmp_path):
    img = _photo(tmp_path / "a.png")
    mm = _ramp_mm().astype(np.float32)
    np.save(tmp_path / "mm.npy", mm)
    with pytest.raises(InputError, match="if the file stores millimetres, pass --depth-scale 0.001"):
        load_input(InputSpec(img, tmp_path / "mm.npy"), CFG)
    depth = load_input(InputSpec(img, tmp_path / "mm.npy", depth_scale=0.001), CFG).depth_m
    np.testing.assert_allclose(depth, mm / 1000.0, rtol=1e-6)


def test_npy_header_declaring_a_huge_array_is_refused_without_allocating_it(tmp_path):
    d = tmp_path / "huge.npy"
    header = "{'descr': '<f4', 'fortran_order': False, 'shape': (200000, 200000), }"
    header += " " * (118 - len(header)) + "\n"
    d.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + b"\x00" * 64)
    with pytest.raises(InputError, match=r"cannot read .*huge\.npy as a \.npy depth array"):
        load_input(InputSpec(_photo(tmp_path / "a.png"), d), CFG)


def test_intrinsics_from_exif_35mm(tmp_path):
    exif = Image.Exif()
    exif.get_ifd(0x8769)[0xA405] = 28  # FocalLengthIn35mmFilm
    img = _photo(tmp_path / "a.jpg", 60, 40, exif=exif)
    k = load_input(InputSpec(img), CFG).intrinsics
    assert k.source == "exif"
    # 28 mm on the 43.27 mm full-frame diagonal; a 3:2 image has the full-frame aspect ratio, so
    # this is also 28 / 36 of the width.
    assert k.fx_px == pytest.approx(28.0 / 36.0 * 60.0, rel=1e-6)
    assert k.fx_px == pytest.approx(28.0 * math.hypot(60, 40) / math.hypot(36, 24))


def test_intrinsics_from_exif_focal_length_and_sensor(tmp_path):
    exif = Image.Exif()
    ifd = exif.get_ifd(0x8769)
    ifd[0x920A] = 4.0  # FocalLength, mm
    ifd[0xA20E] = 10.0  # FocalPlaneXResolution: 10 px per mm
    ifd[0xA210] = 4  # unit: mm
    img = _photo(tmp_path / "a.jpg", 60, 40, exif=exif)
    k = load_input(InputSpec(img), CFG).intrinsics
    assert k.source == "exif" and k.fx_px == pytest.approx(40.0)


def test_exif_orientation_is_applied(tmp_path):
    exif = Image.Exif()
    exif[0x0112] = 6  # rotate 90 degrees clockwise to display
    img = _photo(tmp_path / "a.jpg", 64, 48, exif=exif)
    loaded = load_input(InputSpec(img), CFG)
    assert loaded.rgb.shape == (64, 48, 3)
    assert (loaded.intrinsics.width_px, loaded.intrinsics.height_px) == (48, 64)


def test_default_fov_and_fov_flag(tmp_path):
    img = _photo(tmp_path / "a.png", 64, 48)
    k = load_input(InputSpec(img), CFG).intrinsics
    assert k.source == "default-fov"
    assert k.fx_px == pytest.approx(32.0 / math.tan(math.radians(CFG.default_fov_deg / 2)))
    k90 = load_input(InputSpec(img, fov_deg=90.0), CFG).intrinsics
    assert k90.source == "flag" and k90.fx_px == pytest.approx(32.0)


# ------------------------------------------------------------------------------------------
# Depth formats and downscaling
# ------------------------------------------------------------------------------------------


def test_depth_formats_agree(tmp_path):
    img = _photo(tmp_path / "a.png")
    mm = _ramp_mm()
    mm[0, :] = 0
    from_png = load_input(InputSpec(img, _depth_png(tmp_path / "d.png", mm)), CFG).depth_m
    np.save(tmp_path / "d.npy", mm.astype(np.float64) / 1000.0)
    from_npy = load_input(InputSpec(img, tmp_path / "d.npy"), CFG).depth_m
    Image.fromarray(mm.astype(np.float32) / 1000.0, mode="F").save(tmp_path / "d.tif")
    from_tif = load_input(InputSpec(img, tmp_path / "d.tif"), CFG).depth_m
    Image.fromarray((mm // 20).astype(np.uint8)).save(tmp_path / "d8.png")
    from_8bit = load_input(InputSpec(img, tmp_path / "d8.png", depth_scale=0.02), CFG).depth_m
    assert from_png.dtype == np.float32 and from_png[0].max() == 0.0
    np.testing.assert_allclose(from_png, mm / 1000.0, atol=1e-6)
    np.testing.assert_allclose(from_npy, from_png, atol=1e-6)
    np.testing.assert_allclose(from_tif, from_png, atol=1e-6)
    np.testing.assert_allclose(from_8bit, from_png, atol=0.021)


def test_depth_nearer_than_a_room_sensor_measures_is_invalid_with_a_warning(tmp_path):
    """A Kinect v2 frame holds flying pixels at a few centimetres (esanet_sample: 322 of them,
    which became a 'bowl' 7 cm from the lens): values under MIN_ROOM_DEPTH_M read as invalid
    (0), with a warning that counts them; depth at the limit and beyond is kept."""
    from perception.inputs import MIN_ROOM_DEPTH_M

    img = _photo(tmp_path / "a.png")
    mm = _ramp_mm()
    mm[10:15, 10:20] = 68  # 50 px at 6.8 cm
    mm[20, 10] = int(MIN_ROOM_DEPTH_M * 1000)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        depth = load_input(InputSpec(img, _depth_png(tmp_path / "d.png", mm)), CFG).depth_m
    assert np.all(depth[10:15, 10:20] == 0.0) and depth[20, 10] == pytest.approx(MIN_ROOM_DEPTH_M)
    keep = np.ones(mm.shape, bool)
    keep[10:15, 10:20] = False
    np.testing.assert_allclose(depth[keep], mm[keep] / 1000.0, atol=1e-6)
    near = [w for w in caught if issubclass(w.category, InputWarning) and "nearer than" in str(w.message)]
    assert len(near) == 1 and "50 depth pixels" in str(near[0].message)


def test_large_image_is_downscaled_with_depth_and_intrinsics(tmp_path):
    w, h = 2000, 1500
    photo = np.zeros((h, w, 3), dtype=np.uint8)
    photo[::2, ::2] = 255  # a 1-px checkerboard that any downscaling blurs to grey
    Image.fromarray(photo).save(tmp_path / "big.png")
    mm = np.full((h, w), 2000, dtype=np.uint16)
    mm[:, w // 2 :] = 4000
    _depth_png(tmp_path / "d.png", mm)
    loaded = load_input(InputSpec(tmp_path / "big.png", tmp_path / "d.png", intrinsics=(1500.0, 1500.0, 999.5, 749.5)), CFG)
    assert loaded.rgb.shape == (960, MAX_SIDE_PX, 3) and loaded.depth_m.shape == (960, MAX_SIDE_PX)
    # Nearest neighbour: no depth in between the two walls is invented.
    assert set(np.unique(loaded.depth_m).tolist()) == {2.0, 4.0}
    k = loaded.intrinsics
    assert k.fx_px == pytest.approx(1500.0 * 0.64) and k.cx_px == pytest.approx((MAX_SIDE_PX - 1) / 2)
    # the photo itself is kept at full resolution, untouched (textures are built from it)
    assert loaded.rgb_full is not None and np.array_equal(loaded.rgb_full, photo)
    small = load_input(InputSpec(tmp_path / "big.png"), CFG)
    assert small.rgb_full is not None and small.rgb.shape[1] == MAX_SIDE_PX


def test_small_image_keeps_no_second_copy(tmp_path):
    Image.fromarray(np.zeros((480, 640, 3), dtype=np.uint8)).save(tmp_path / "vga.png")
    loaded = load_input(InputSpec(tmp_path / "vga.png"), CFG)
    assert loaded.rgb.shape == (480, 640, 3) and loaded.scale == 1.0 and loaded.rgb_full is None


def test_a_bug_while_reading_is_not_reported_as_a_bad_file(tmp_path, monkeypatch):
    """Only what Pillow / numpy raise for an unreadable file becomes an InputError: an error of
    scene-builder's own code while reading a good file surfaces as itself (it used to read
    'cannot read ... as an image', blaming the user's photo)."""
    import perception.inputs as inputs

    photo = tmp_path / "photo.png"
    Image.fromarray(np.zeros((32, 32, 3), np.uint8)).save(photo)

    def buggy(*args, **kwargs):
        raise AttributeError("'NoneType' object has no attribute 'mode'")

    monkeypatch.setattr(inputs, "_to_rgb", buggy)
    with pytest.raises(AttributeError):
        inputs.load_rgb(photo)
    # and a file that really is broken is still one InputError line
    (tmp_path / "cut.png").write_bytes(photo.read_bytes()[:60])
    monkeypatch.undo()
    with pytest.raises(InputError, match=r"cannot read .*cut\.png as an image"):
        inputs.load_rgb(tmp_path / "cut.png")


def test_a_photos_flat_frame_is_found_and_textured_from_inside():
    """An undistorted Kinect frame's white padding (5 px top and bottom, 6 left, 7 right, each
    with a blended line inside) is found and replaced by the pixels next to it; a black border on
    one side likewise; a photo whose edge is merely bright but varied has no frame."""
    from perception.inputs import photo_frame, without_frame

    rng = np.random.default_rng(0)
    inner = rng.integers(40, 200, (300, 400, 3), dtype=np.uint8)  # frame caps: 9 rows, 12 columns
    framed = inner.copy()
    framed[5], framed[-6], framed[:, 6], framed[:, -8] = 215, 215, 215, 215  # the blended lines
    framed[:5], framed[-5:], framed[:, :6], framed[:, -7:] = 255, 255, 255, 255
    frame = photo_frame(framed)
    assert frame == (6, 6, 7, 8)
    out = without_frame(framed, frame)
    assert out.shape == framed.shape and out.max() < 200  # no white, no blend left
    np.testing.assert_array_equal(out[6:-6, 7:-8], framed[6:-6, 7:-8])
    np.testing.assert_array_equal(out[0, 7:-8], framed[6, 7:-8])
    np.testing.assert_array_equal(out[6:-6, -1], framed[6:-6, -9])
    black = inner.copy()
    black[:, :2] = 0
    assert photo_frame(black) == (0, 0, 3, 0)
    bright = inner.copy()
    bright[:3] = rng.integers(180, 256, (3, 400, 3), dtype=np.uint8)
    assert photo_frame(bright) == (0, 0, 0, 0)
    assert without_frame(inner, (0, 0, 0, 0)) is inner
