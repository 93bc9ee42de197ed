"""A built scene seen from other cameras: renders of its MJCF from any pose, the controls that
do nothing clever, and the figures a view is scored on.

Rendering
---------
:func:`render_mjcf` loads a written ``scene.xml`` with ``mujoco.MjSpec``, adds one camera per
requested pose (``scene_builder.frames.mujoco_camera``: an OpenCV pinhole reproduced to < 0.2 px,
principal point included) and renders RGB (the scene's own lights) and metric planar depth
(0 where nothing is hit). The depth comes from MuJoCo's depth buffer in the same pass as the
colour, of the file a simulator loads: what is scored is what a user of the twin sees, the
drawn floor past the observed one included. Open3D's ``RaycastingScene`` was measured against
it (``python -m scene_builder.bench.viewpoints OUT``, :func:`raycast_check`, on two real builds
of ``../shared/data/multiview``, 2026-11-25, 2 loaded cores): both depth maps agree on 99.9 % of
the pixels to a median 0.15 % (99th percentile 3-11 %: pixels on occluding edges); Open3D's
scene build and one cast took 0.7 s, MuJoCo's renderer set-up and first pass 1.3-1.5 s and each
further pass 0.14-0.19 s. The colour needs MuJoCo's renderer anyway (textures, lights), and a
view is scored on colour and depth, so with the renderer up MuJoCo's depth pass is the cheaper
one: MuJoCo renders both, one renderer per image size for all the cameras.

Controls
--------
* :func:`background_only`: the build with every object removed (the everything-background
  control: the photo on the observed depth, holes behind objects filled).
* :func:`photo_on_box`: the input photo on the room's fitted planes alone (floor, walls, a
  ceiling at the top of the observed background): each pixel's ray stops at the first plane it
  meets. The planes are analytic, so that is one line of numpy per plane (a ray-casting library
  would need them meshed first).

Scores (:func:`score_view`)
---------------------------
Against a true view (depth, 0 where invalid; RGB): ``within10`` = pixels of valid true depth
where the twin's depth is within 10 % of it / pixels of valid true depth (a pixel the twin does
not cover counts as a miss); ``absrel_median`` = median ``|d - d*| / d*`` over pixels both have;
``coverage`` = pixels both have / valid true pixels; PSNR and SSIM (scikit-image) of the RGB
render against the true photo over the whole image. With the true view's :func:`visibility`
from the input camera, ``within10`` is split into the pixels whose 3D point the input camera
saw, had in view but did not see (hidden behind something, or no depth measured there: what
completion has to get right) and had out of view (what one photo cannot show).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scene_builder import frames
from scene_builder.model import Background, CameraIntrinsics, Plane, Room, Scene, Texture, TriangleMesh

__all__ = [
    "REL_TOL",
    "View",
    "ViewScore",
    "background_only",
    "photo_on_box",
    "render_mjcf",
    "score_view",
    "visibility",
]

#: A pixel is right when its depth is within this share of the true depth.
REL_TOL = 0.10
#: A true point counts as seen by the input camera when its depth there is at most this share
#: beyond what the input camera measured at its pixel (not hidden behind something).
SEEN_TOL = 0.05
#: The photo-on-a-box control's grid: one node every this many pixels.
BOX_STRIDE_PX = 4


@dataclass(frozen=True, eq=False)
class View:
    """A render: rgb (H, W, 3) uint8; depth_m (H, W) float32 planar depth, 0 where nothing."""

    rgb: np.ndarray
    depth_m: np.ndarray


def render_mjcf(mjcf_path: Path, cameras, objects_only: bool = False) -> list[View]:
    """Render ``mjcf_path`` at t = 0 from each ``(world_from_camera, intrinsics)`` of ``cameras``
    (the scene's world frame, OpenCV axes). objects_only: hide geom group 0 (the background
    surface, the drawn floor, what became background) and the room's planes, so only the objects
    (visual group 1) show."""
    import mujoco

    spec = mujoco.MjSpec.from_file(str(mjcf_path))
    from scene_builder.bench.render import add_camera

    for i, (world_from_camera, k) in enumerate(cameras):
        add_camera(spec, f"bench/view_{i}", world_from_camera, k)
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    option = mujoco.MjvOption()
    if objects_only:
        option.geomgroup[:] = 0
        option.geomgroup[1] = 1
    far = float(model.stat.extent * model.vis.map.zfar)
    out = []
    renderers: dict[tuple[int, int], object] = {}  # one per image size: its set-up (GL context, upload) costs seconds
    try:
        for i, (_, k) in enumerate(cameras):
            size = (k.height_px, k.width_px)
            r = renderers.get(size) or renderers.setdefault(size, mujoco.Renderer(model, *size))
            r.disable_depth_rendering()
            r.update_scene(data, camera=f"bench/view_{i}", scene_option=option)
            rgb = r.render().copy()
            r.enable_depth_rendering()
            r.update_scene(data, camera=f"bench/view_{i}", scene_option=option)
            depth = r.render().astype(np.float32)
            depth[depth >= 0.999 * far] = 0.0
            out.append(View(rgb, depth))
    finally:
        for r in renderers.values():
            r.close()
    return out


# --------------------------------------------------------------------------------------------
# Controls
# --------------------------------------------------------------------------------------------


def background_only(scene: Scene) -> Scene:
    """The everything-background control: the same scene with no object."""
    return dataclasses.replace(scene, objects=())


def _box_planes(scene: Scene) -> list[Plane]:
    planes = [Plane(np.array([0.0, 0.0, 1.0]), 0.0, "floor"), *scene.room.walls]
    bg = scene.room.background
    if bg is not None and bg.surface_observed.any():
        top = float(np.percentile(bg.surface.vertices_m[bg.surface_observed, 2], 99.5))
        if top > scene.camera.position_m[2] + 0.1:  # a ceiling above the camera was seen (or the tallest thing was)
            planes.append(Plane(np.array([0.0, 0.0, -1.0]), top, "ceiling"))
    return planes


def _max_depth_m(scene: Scene) -> float:
    """MAX_FILL_FACTOR times the farthest observed background depth (10 m without a background)."""
    from perception.background import MAX_FILL_FACTOR

    bg = scene.room.background
    if bg is None or not bg.surface_observed.any():
        return 10.0
    cam_from_world = np.linalg.inv(scene.camera.world_from_camera)
    z = frames.transform_points(cam_from_world, bg.surface.vertices_m[bg.surface_observed])[:, 2]
    return float(MAX_FILL_FACTOR * z.max())


def photo_on_box(scene: Scene, photo_rgb: np.ndarray) -> Scene:
    """The photo-on-a-box control: ``photo_rgb`` (the input photo, any size) on the room's fitted
    planes only (floor z = 0, the walls, a ceiling at the 99.5th percentile height of the
    observed background when that is above the camera), no objects and no other background. A
    grid node every :data:`BOX_STRIDE_PX` pixels stops where its ray first meets a plane, no
    farther than the background's own depth cap (``perception.background.MAX_FILL_FACTOR`` times
    the farthest observed depth); grid cells with a corner whose ray meets none are left out."""
    k = scene.camera.intrinsics
    w, h = k.width_px, k.height_px
    xs = np.unique(np.append(np.arange(0, w, BOX_STRIDE_PX), w - 1)).astype(np.float64)
    ys = np.unique(np.append(np.arange(0, h, BOX_STRIDE_PX), h - 1)).astype(np.float64)
    uu, vv = np.meshgrid(xs, ys)
    rays_cam = np.stack([(uu - k.cx_px) / k.fx_px, (vv - k.cy_px) / k.fy_px, np.ones_like(uu)], axis=-1).reshape(-1, 3)
    r, c = scene.camera.world_from_camera[:3, :3], scene.camera.world_from_camera[:3, 3]
    d_world = rays_cam @ r.T
    t = np.full(len(rays_cam), np.inf)
    for plane in _box_planes(scene):
        denom = d_world @ plane.normal
        dist = float(plane.normal @ c + plane.offset_m)
        with np.errstate(divide="ignore", invalid="ignore"):
            tk = np.where(denom < -1e-9, -dist / denom, np.inf)
        t = np.minimum(t, np.where(tk > 0, tk, np.inf))
    # Planar depth (rays_cam has z = 1) capped like the background's fill: a ray nearly parallel
    # to a plane would meet it kilometres away, and MuJoCo scales its clipping planes with the
    # model's extent, so one such vertex would clip the whole room away.
    hit = np.isfinite(t) & (t <= _max_depth_m(scene))
    verts = c + d_world * np.where(hit, t, 0.0)[:, None]
    nx, ny = len(xs), len(ys)
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, cc, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    ok = hit[a] & hit[b] & hit[cc] & hit[d]
    # Counter-clockwise seen from the camera (image y runs down).
    faces = np.concatenate([np.stack([a, cc, b], axis=1)[ok], np.stack([b, cc, d], axis=1)[ok]])
    used = np.unique(faces)
    remap = np.full(len(verts), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    uv = np.stack([(uu.ravel() + 0.5) / w, (vv.ravel() + 0.5) / h], axis=1)[used]
    mesh = TriangleMesh(verts[used], remap[faces], uv=np.clip(uv, 0.0, 1.0), texture=Texture("background", np.ascontiguousarray(photo_rgb[..., :3], dtype=np.uint8)))
    room = Room(walls=scene.room.walls, background=Background(surface=mesh, surface_observed=np.ones(len(used), dtype=bool)))
    return dataclasses.replace(scene, room=room, objects=())


# --------------------------------------------------------------------------------------------
# Scores
# --------------------------------------------------------------------------------------------


#: Labels of :func:`visibility`.
INVALID, SEEN, HIDDEN, OUTSIDE = 0, 1, 2, 3


def visibility(depth_b_m: np.ndarray, k_b: CameraIntrinsics, a_from_b: np.ndarray, depth_a_m: np.ndarray, k_a: CameraIntrinsics) -> np.ndarray:
    """(H_b, W_b) uint8 label of each pixel of view B as camera A saw its 3D point: :data:`SEEN`
    (it projects into A's image in front of A, where A has valid depth, at most
    :data:`SEEN_TOL` beyond it), :data:`HIDDEN` (in A's image but behind what A saw, or where A
    measured nothing), :data:`OUTSIDE` (outside A's image or behind A), :data:`INVALID` (no true
    depth in B). ``a_from_b``: camera B's frame to camera A's. What A saw is its depth map (the
    real frames have no mesh to ray cast against), so this is a z-test against that map."""
    valid = depth_b_m > 0
    pts_a = frames.transform_points(a_from_b, k_b.unproject(np.where(valid, depth_b_m, 0.0))[valid])
    z = pts_a[:, 2]
    front = z > 1e-3
    uv = np.full((len(z), 2), -1.0)
    uv[front] = k_a.project(pts_a[front])
    u, v = np.round(uv[:, 0]).astype(np.int64), np.round(uv[:, 1]).astype(np.int64)
    inside = front & (u >= 0) & (u < k_a.width_px) & (v >= 0) & (v < k_a.height_px)
    d_a = np.zeros(len(z))
    d_a[inside] = depth_a_m[v[inside], u[inside]]
    seen = inside & (d_a > 0) & (z <= d_a * (1.0 + SEEN_TOL))
    out = np.full(depth_b_m.shape, INVALID, dtype=np.uint8)
    out[valid] = np.where(seen, SEEN, np.where(inside, HIDDEN, OUTSIDE))
    return out


@dataclass(frozen=True)
class ViewScore:
    """One render against one true view (definitions in the module docstring). valid_px: the
    denominator (pixels with valid true depth); with visibility labels, ``within10`` again over
    the valid pixels the input camera saw, had in view but did not see (hidden or unmeasured),
    and had out of view, with their counts (None without labels)."""

    valid_px: int
    within10: float | None
    absrel_median: float | None
    coverage: float | None
    psnr_db: float | None
    ssim: float | None
    seen_px: int | None = None
    within10_seen: float | None = None
    hidden_px: int | None = None
    within10_hidden: float | None = None
    outside_px: int | None = None
    within10_outside: float | None = None


def score_view(view: View, true_depth_m: np.ndarray, true_rgb: np.ndarray | None = None, labels: np.ndarray | None = None) -> ViewScore:
    """Score ``view`` against the true depth (0 = invalid) and photo of the same camera (PSNR and
    SSIM inside the photo's flat frame, ``perception.inputs.photo_frame``); ``labels``:
    :func:`visibility` of the true view from the input camera."""
    valid = np.asarray(true_depth_m) > 0
    n = int(valid.sum())
    pred = view.depth_m.astype(np.float64)
    covered = valid & (pred > 0)
    rel = np.full(true_depth_m.shape, np.inf)
    rel[covered] = np.abs(pred[covered] - true_depth_m[covered]) / true_depth_m[covered]
    good = valid & (rel < REL_TOL)
    psnr = ssim = None
    if true_rgb is not None:
        from skimage.metrics import peak_signal_noise_ratio, structural_similarity

        from perception.inputs import photo_frame

        photo = np.asarray(true_rgb)[..., :3]
        # Inside the photo's flat frame (Kinect / NYU undistortion pads 6-8 px of white): those
        # pixels show no scene, and the twin paints its border from the pixels inside.
        top, bottom, left, right = photo_frame(photo)
        inner = (slice(top, photo.shape[0] - bottom), slice(left, photo.shape[1] - right))
        psnr = float(peak_signal_noise_ratio(photo[inner], view.rgb[inner], data_range=255))
        ssim = float(structural_similarity(photo[inner], view.rgb[inner], channel_axis=2, data_range=255))
    extra = {}
    if labels is not None:
        for name, label in (("seen", SEEN), ("hidden", HIDDEN), ("outside", OUTSIDE)):
            sel = valid & (labels == label)
            extra[f"{name}_px"] = int(sel.sum())
            extra[f"within10_{name}"] = float((good & sel).sum() / sel.sum()) if sel.any() else None
    return ViewScore(
        valid_px=n,
        within10=float(good.sum() / n) if n else None,
        absrel_median=float(np.median(rel[covered])) if covered.any() else None,
        coverage=float(covered.sum() / n) if n else None,
        psnr_db=psnr,
        ssim=ssim,
        **extra,
    )


# --------------------------------------------------------------------------------------------
# MuJoCo's depth against Open3D's ray casting (the choice made in the module docstring)
# --------------------------------------------------------------------------------------------


def raycast_check(mjcf_path: Path) -> dict:
    """Depth of ``mjcf_path`` from ``input_camera`` at t = 0, rendered by MuJoCo and ray cast by
    Open3D's ``RaycastingScene`` against the same compiled model's drawn meshes and planes
    (groups 0-1). Both start from the loaded model (``load_s``, shared); ``mujoco_s``: a renderer
    and one depth pass, ``mujoco_again_s``: one more depth pass with it; ``open3d_s``: the
    ray-casting scene built and one cast. Then how far the two depth maps agree."""
    import time

    import mujoco
    import open3d as o3d

    t0 = time.perf_counter()
    model = mujoco.MjModel.from_xml_path(str(mjcf_path))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    load_s = time.perf_counter() - t0
    cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "input_camera")
    w, h = (int(x) for x in model.cam_resolution[cid])
    sw, sh = (float(x) for x in model.cam_sensorsize[cid])
    f_x, f_y, p_x, p_y = (float(x) for x in model.cam_intrinsic[cid])
    k = CameraIntrinsics(f_x * w / sw, f_y * h / sh, (w - 1) / 2.0 - p_x * w / sw, (h - 1) / 2.0 - p_y * h / sh, w, h, "file")
    t0 = time.perf_counter()
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), w)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), h)
    with mujoco.Renderer(model, h, w) as r:
        r.enable_depth_rendering()
        r.update_scene(data, camera=cid)
        mj = r.render().astype(np.float64)
        mujoco_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        r.update_scene(data, camera=cid)
        r.render()
        mujoco_again_s = time.perf_counter() - t1
    mj[mj >= 0.999 * float(model.stat.extent * model.vis.map.zfar)] = 0.0
    t0 = time.perf_counter()
    scene = o3d.t.geometry.RaycastingScene()
    for g in range(model.ngeom):
        if model.geom_group[g] > 1 or model.geom_rgba[g][3] == 0:
            continue
        rot, pos = data.geom_xmat[g].reshape(3, 3), data.geom_xpos[g]
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            mid = model.geom_dataid[g]
            va, vn, fa, fn = model.mesh_vertadr[mid], model.mesh_vertnum[mid], model.mesh_faceadr[mid], model.mesh_facenum[mid]
            v, f = model.mesh_vert[va : va + vn] @ rot.T + pos, model.mesh_face[fa : fa + fn]
        elif model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE:
            sx, sy = model.geom_size[g][:2]
            v, f = np.array([[-sx, -sy, 0], [sx, -sy, 0], [sx, sy, 0], [-sx, sy, 0]]) @ rot.T + pos, np.array([[0, 1, 2], [0, 2, 3]])
        else:
            continue
        scene.add_triangles(o3d.core.Tensor(np.asarray(v, dtype=np.float32)), o3d.core.Tensor(np.asarray(f, dtype=np.uint32)))
    t_cam = np.eye(4)
    t_cam[:3, :3] = data.cam_xmat[cid].reshape(3, 3) @ frames.CV_FROM_GL
    t_cam[:3, 3] = data.cam_xpos[cid]
    cam_from_world = np.linalg.inv(t_cam)
    rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(o3d.core.Tensor(k.matrix), o3d.core.Tensor(cam_from_world), w, h)
    t_hit = scene.cast_rays(rays)["t_hit"].numpy()
    z_per_t = (rays.numpy()[..., 3:] @ cam_from_world[:3, :3].T)[..., 2]
    o3 = np.where(np.isfinite(t_hit), t_hit * z_per_t, 0.0)
    open3d_s = time.perf_counter() - t0
    both = (mj > 0) & (o3 > 0)
    rel = np.abs(mj[both] - o3[both]) / o3[both]
    return {
        "load_s": load_s, "mujoco_s": mujoco_s, "mujoco_again_s": mujoco_again_s, "open3d_s": open3d_s, "pixels_both": float(both.mean()),
        "pixels_only_mujoco": float(((mj > 0) & (o3 <= 0)).mean()), "pixels_only_open3d": float(((mj <= 0) & (o3 > 0)).mean()),
        "rel_diff_median": float(np.median(rel)) if rel.size else None, "rel_diff_p99": float(np.percentile(rel, 99)) if rel.size else None,
    }


def main(argv: list[str] | None = None) -> int:
    """``python -m scene_builder.bench.viewpoints OUT [OUT ...]``: :func:`raycast_check` per build."""
    import json
    import sys

    args = list(sys.argv[1:] if argv is None else argv)
    if not args:
        print("usage: python -m scene_builder.bench.viewpoints OUT [OUT ...] (folders written by scene-builder build)", file=sys.stderr)
        return 2
    for out in args:
        print(json.dumps({"out": out, **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in raycast_check(Path(out) / "scene.xml").items()}}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
