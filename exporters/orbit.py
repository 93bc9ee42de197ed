"""A sheet of views of a written scene (``scene-builder view OUT --orbit PNG``): what the twin is
in 3D, not only from the photo's camera, where a painted backdrop would look right too.

Top row, the whole twin: the photo (from ``report.json``'s input, when it is still there), the
render from ``input_camera``, orbits of -30 and +30 degrees about the objects (15 degrees higher),
and a view from above. Bottom row, the same cameras with the objects alone (visual group 1: no
background surface, drawn floor or walls). Rendered offscreen with MuJoCo at t = 0
(``MUJOCO_GL=egl`` without a display) from ``scene.xml``.

The orbit turns about the vertical axis through the median of the objects' body positions (2.5 m
in front of the camera when there is none), at the input camera's distance to it: MuJoCo's free
camera (``mjCAMERA_FREE``) sits at ``lookat - distance * (cos el cos az, cos el sin az, sin el)``,
so the input camera's own direction to that point gives the azimuth and elevation to start from.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from scene_builder.errors import InputError

__all__ = ["ORBIT_DEG", "orbit_sheet", "orbit_views"]

#: Turns of the orbit views about the vertical through the objects.
ORBIT_DEG = (-30.0, 30.0)
#: The orbit views look down this much more than the input camera; the view from above looks
#: down at this elevation.
ORBIT_RAISE_DEG = 15.0
TOP_ELEVATION_DEG = -75.0
#: The orbit cameras stand this many times the input camera's distance from the objects, the
#: view from above TOP_DISTANCE times: far enough to show the room around them.
ORBIT_DISTANCE = 1.5
TOP_DISTANCE = 2.0
#: Each panel of the sheet is the render scaled by this factor.
PANEL_SCALE = 0.5
TITLES = ("photo", "input camera", "orbit -30 deg", "orbit +30 deg", "from above")


def _look_at(m, d, cam_pos: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Median position of the bodies that are objects (root bodies other than the world, without
    the robot and the probes), else 2.5 m ahead of the camera."""
    import mujoco

    pts = []
    for b in range(1, m.nbody):
        if m.body_parentid[b] != 0:
            continue
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or ""
        if name.startswith(("robot/", "probe/")):
            continue
        pts.append(d.xpos[b].copy())
    return np.median(np.array(pts), axis=0) if pts else cam_pos + 2.5 * forward


def orbit_views(mjcf_path: Path) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(whole twin, objects only): the renders from the input camera, the orbits and from
    above, each (H, W, 3) uint8 at the input camera's resolution."""
    import mujoco

    mjcf_path = Path(mjcf_path)
    if not mjcf_path.is_file():
        raise InputError(f"no scene at {mjcf_path}; pass a folder written by `scene-builder build`")
    m = mujoco.MjModel.from_xml_path(str(mjcf_path))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    cid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "input_camera")
    if cid < 0:
        raise InputError(f"{mjcf_path} has no camera 'input_camera'; it was not written by scene-builder")
    w, h = (int(x) for x in m.cam_resolution[cid]) if m.cam_resolution[cid].all() else (640, 480)
    m.vis.global_.offwidth = max(int(m.vis.global_.offwidth), w)
    m.vis.global_.offheight = max(int(m.vis.global_.offheight), h)
    # The free cameras get the input camera's vertical field of view.
    fy = float(m.cam_intrinsic[cid][1]) * h / float(m.cam_sensorsize[cid][1]) if m.cam_sensorsize[cid].any() else None
    if fy:
        m.vis.global_.fovy = float(np.degrees(2.0 * np.arctan(h / 2.0 / fy)))
    cam_pos = d.cam_xpos[cid].copy()
    forward = -d.cam_xmat[cid].reshape(3, 3)[:, 2]
    look = _look_at(m, d, cam_pos, forward)
    dist = max(float(np.linalg.norm(look - cam_pos)), 1.0)
    f = (look - cam_pos) / max(float(np.linalg.norm(look - cam_pos)), 1e-9)
    az0, el0 = np.degrees(np.arctan2(f[1], f[0])), np.degrees(np.arcsin(np.clip(f[2], -1.0, 1.0)))

    def free(az: float, el: float, distance: float):
        c = mujoco.MjvCamera()
        c.type = mujoco.mjtCamera.mjCAMERA_FREE
        c.lookat[:] = look
        c.distance, c.azimuth, c.elevation = distance, az, el
        return c

    cameras = [cid] + [free(az0 + a, el0 - ORBIT_RAISE_DEG, dist * ORBIT_DISTANCE) for a in ORBIT_DEG] + [free(az0, TOP_ELEVATION_DEG, dist * TOP_DISTANCE)]
    whole, objects = [], []
    objects_only = mujoco.MjvOption()
    objects_only.geomgroup[:] = 0
    objects_only.geomgroup[1] = 1
    with mujoco.Renderer(m, h, w) as r:
        for c in cameras:
            r.update_scene(d, camera=c)
            whole.append(r.render().copy())
            r.update_scene(d, camera=c, scene_option=objects_only)
            objects.append(r.render().copy())
    return whole, objects


def _photo(out_dir: Path) -> np.ndarray | None:
    """The input photo named in OUT/report.json, when it can still be read."""
    from PIL import Image, ImageOps, UnidentifiedImageError

    try:
        path = json.loads((out_dir / "report.json").read_text())["input"]["image"]
        with Image.open(path) as im:
            return np.asarray(ImageOps.exif_transpose(im).convert("RGB"))
    except (OSError, KeyError, TypeError, ValueError, UnidentifiedImageError):  # no report, no photo there any more: the panel stays blank
        return None


def orbit_sheet(out_dir: Path, png: Path) -> Path:
    """Write the sheet of ``out_dir``'s scene to ``png`` (PNG, or JPEG by its suffix); returns ``png``."""
    from PIL import Image, ImageDraw

    out_dir = Path(out_dir)
    whole, objects = orbit_views(out_dir / "scene.xml")
    h, w = whole[0].shape[:2]
    pw, ph = max(1, int(round(w * PANEL_SCALE))), max(1, int(round(h * PANEL_SCALE)))
    photo = _photo(out_dir)
    top = [photo if photo is not None else np.zeros_like(whole[0]), *whole]
    bottom = [None, *objects]
    sheet = Image.new("RGB", (pw * len(top), ph * 2), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    def title(x: int, y: int, text: str) -> None:
        box = draw.textbbox((x, y), text)
        draw.rectangle((box[0] - 3, box[1] - 2, box[2] + 3, box[3] + 2), fill=(0, 0, 0))
        draw.text((x, y), text, fill=(255, 255, 0))

    for i, (a, b) in enumerate(zip(top, bottom)):
        sheet.paste(Image.fromarray(a).resize((pw, ph), Image.LANCZOS), (i * pw, 0))
        title(i * pw + 6, 4, TITLES[i])
        if b is not None:
            sheet.paste(Image.fromarray(b).resize((pw, ph), Image.LANCZOS), (i * pw, ph))
            title(i * pw + 6, ph + 4, TITLES[i] + ", objects only")
    draw.text((6, ph + 4), "whole twin above,\nobjects alone below", fill=(0, 0, 0))
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(png, quality=85) if png.suffix.lower() in (".jpg", ".jpeg") else sheet.save(png, optimize=True)
    return png
