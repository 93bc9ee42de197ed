"""Procedural rooms in MuJoCo: the ``mujoco.MjSpec`` of a :class:`~scene_builder.bench.procedural.RoomSpec`,
its RGB / metric depth / instance renders from the input camera, and the sample folder written in
the format of ``../shared/data/real/*`` (see :mod:`scene_builder.bench.procedural` for the
ground-truth conventions).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scene_builder import frames
from scene_builder.bench.procedural import DENSITY_KG_M3, DepthNoise, Look, RoomSpec, make_room
from scene_builder.model import Camera

__all__ = [
    "RenderedRoom",
    "build_mjspec",
    "corrupt_depth",
    "ground_truth",
    "orbit_cameras",
    "render_arrays",
    "render_room",
    "render_views",
    "write_demo_input",
]

# --------------------------------------------------------------------------------------------
# MuJoCo scene
# --------------------------------------------------------------------------------------------


def build_mjspec(spec: RoomSpec, free_bodies: bool = True):
    """The room as a ``mujoco.MjSpec``: floor ``floor`` and walls ``wall_k`` (planes), each object a
    body ``NAME`` (a free joint ``NAME/free`` when ``free_bodies``) with moving parts as child
    bodies ``NAME/PART`` on joints ``NAME/PART/joint``, and the camera ``input_camera``."""
    import mujoco

    ms = mujoco.MjSpec()
    ms.modelname = spec.name
    ms.option.timestep = 0.002
    k = spec.camera.intrinsics
    ms.visual.global_.offwidth = max(640, k.width_px)
    ms.visual.global_.offheight = max(480, k.height_px)
    ms.visual.headlight.ambient = [0.4, 0.4, 0.4]
    ms.visual.headlight.diffuse = [0.35, 0.35, 0.35]
    ms.visual.quality.shadowsize = 2048

    materials: dict[Look, str] = {}

    def material(look: Look, plane: bool) -> str:
        key = (look, plane)
        if key in materials:
            return materials[key]
        name = f"mat_{len(materials)}"
        mat = ms.add_material(name=name, rgba=list(look.rgba), specular=0.1, shininess=0.1)
        if look.texture:
            tex = ms.add_texture(name=f"tex_{len(materials)}", type=mujoco.mjtTexture.mjTEXTURE_2D if plane else mujoco.mjtTexture.mjTEXTURE_CUBE)
            tex.width, tex.height = 128, 128
            tex.rgb1 = list(look.rgba[:3])
            tex.rgb2 = list(look.rgba2[:3])
            if look.texture == "checker":
                tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_CHECKER
            elif look.texture == "gradient":
                tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_GRADIENT
            else:
                tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_FLAT
                tex.mark = mujoco.mjtMark.mjMARK_RANDOM
                tex.random = 0.08
                tex.markrgb = list(look.rgba2[:3])
            mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = tex.name
            mat.rgba = [1.0, 1.0, 1.0, 1.0]
            mat.texrepeat = list(look.texrepeat)
            mat.texuniform = plane
        materials[key] = name
        return name

    wb = ms.worldbody
    lx, ly, lz = spec.room_size_m
    wb.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[lx / 2 + 0.5, ly / 2 + 0.5, 0.05],
        pos=[lx / 2, ly / 2, 0.0],
        material=material(spec.floor_look, True),
    )
    for wall in spec.walls:
        n = np.asarray(wall.normal)
        # Plane geoms face their local +Z: rotate +Z onto the wall normal, keep local +Y up.
        r = np.stack([np.cross([0.0, 0.0, 1.0], n), [0.0, 0.0, 1.0], n], axis=1)
        wb.add_geom(
            name=wall.name,
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[wall.half_length_m + 0.5, wall.height_m / 2, 0.05],
            pos=list(wall.center_m),
            quat=list(frames.quat_wxyz_from_matrix(r)),
            material=material(wall.look, True),
        )
    wb.add_geom(
        name="ceiling",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[lx / 2 + 0.5, ly / 2 + 0.5, 0.05],
        pos=[lx / 2, ly / 2, lz],
        quat=[0.0, 1.0, 0.0, 0.0],
        rgba=[0.92, 0.92, 0.9, 1.0],
        contype=0,
        conaffinity=0,
    )
    wb.add_light(name="ceiling_light", pos=list(spec.light_pos_m), dir=[0.0, 0.0, -1.0], diffuse=[0.5, 0.5, 0.5], cutoff=80.0, castshadow=True)
    cam = frames.mujoco_camera(spec.camera.world_from_camera, k)
    c = wb.add_camera(name="input_camera", pos=list(cam["pos"]), quat=list(cam["quat"]))
    c.resolution = list(cam["resolution"])
    c.focal_pixel = list(cam["focalpixel"])
    c.principal_pixel = list(cam["principalpixel"])
    c.sensor_size = list(cam["sensorsize"])

    shape_type = {"box": mujoco.mjtGeom.mjGEOM_BOX, "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER, "ellipsoid": mujoco.mjtGeom.mjGEOM_ELLIPSOID}
    for obj in spec.objects:
        w_from_o = obj.world_from_object
        body = wb.add_body(name=obj.name, pos=list(w_from_o[:3, 3]), quat=list(frames.quat_wxyz_from_matrix(w_from_o[:3, :3])))
        if free_bodies:
            body.add_freejoint(name=f"{obj.name}/free")
        bodies = {"": body}
        for j in obj.joints:
            child = body.add_body(name=f"{obj.name}/{j.part}")
            jt = mujoco.mjtJoint.mjJNT_HINGE if j.type == "revolute" else mujoco.mjtJoint.mjJNT_SLIDE
            child.add_joint(name=f"{obj.name}/{j.part}/joint", type=jt, axis=list(j.axis), pos=list(j.anchor_m), range=[j.lower, j.upper], limited=1, damping=1.0)
            bodies[j.part] = child
        density = DENSITY_KG_M3[obj.category]
        for i, p in enumerate(obj.primitives):
            half = list(p.half_size_m) if p.shape != "cylinder" else [p.half_size_m[0], p.half_size_m[2], 0.0]
            bodies[p.body].add_geom(
                name=f"{obj.name}/g{i}",
                type=shape_type[p.shape],
                size=half,
                pos=list(p.center_m),
                density=density,
                material=material(p.look, False),
            )
    return ms


# --------------------------------------------------------------------------------------------
# Rendering and writing the sample folder
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RenderedRoom:
    """rgb: (H, W, 3) uint8; depth_m: (H, W) float32 clean planar depth (0 where nothing);
    instances: (H, W) uint16 object ids (0 = background)."""

    rgb: np.ndarray
    depth_m: np.ndarray
    instances: np.ndarray


def render_arrays(spec: RoomSpec) -> RenderedRoom:
    """Render the room from ``input_camera``: RGB, clean metric planar depth and instance ids."""
    return render_views(spec, (spec.camera,))[0]


def add_camera(spec, name: str, world_from_camera: np.ndarray, k) -> None:
    """Add an OpenCV pinhole camera (``world_from_camera`` (4, 4), intrinsics ``k``) to the
    MjSpec ``spec`` under ``name``, and make its offscreen buffer large enough for it."""
    cam = frames.mujoco_camera(np.asarray(world_from_camera, dtype=np.float64), k)
    c = spec.worldbody.add_camera(name=name, pos=list(cam["pos"]), quat=list(cam["quat"]))
    c.resolution = list(cam["resolution"])
    c.focal_pixel = list(cam["focalpixel"])
    c.principal_pixel = list(cam["principalpixel"])
    c.sensor_size = list(cam["sensorsize"])
    spec.visual.global_.offwidth = max(spec.visual.global_.offwidth, k.width_px)
    spec.visual.global_.offheight = max(spec.visual.global_.offheight, k.height_px)


def render_views(spec: RoomSpec, cameras) -> list[RenderedRoom]:
    """Render the room from each :class:`~scene_builder.model.Camera` of ``cameras`` (world
    frame of the room, OpenCV axes, their own intrinsics): RGB, clean metric planar depth and
    instance ids, as :func:`render_arrays` does for the input camera."""
    import mujoco

    ms = build_mjspec(spec, free_bodies=False)
    for i, camera in enumerate(cameras):
        add_camera(ms, f"bench/view_{i}", camera.world_from_camera, camera.intrinsics)
    model = ms.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    geom_to_id = np.zeros(model.ngeom + 1, dtype=np.uint16)  # index -1 (background) -> 0
    ids = {o.name: o.object_id for o in spec.objects}
    for g in range(model.ngeom):
        root = model.body_rootid[model.geom_bodyid[g]]
        geom_to_id[g] = ids.get(model.body(root).name, 0)
    far = float(model.stat.extent * model.vis.map.zfar)
    out = []
    for i, camera in enumerate(cameras):
        k = camera.intrinsics
        with mujoco.Renderer(model, k.height_px, k.width_px) as r:
            r.update_scene(data, camera=f"bench/view_{i}")
            rgb = r.render().copy()
            r.enable_depth_rendering()
            r.update_scene(data, camera=f"bench/view_{i}")
            depth = r.render().astype(np.float32)
            r.disable_depth_rendering()
            r.enable_segmentation_rendering()
            r.update_scene(data, camera=f"bench/view_{i}")
            seg = r.render()
        geom_ids = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)
        depth[depth >= 0.999 * far] = 0.0
        out.append(RenderedRoom(rgb, depth, geom_to_id[geom_ids].astype(np.uint16)))
    return out


def orbit_cameras(spec: RoomSpec, degrees=(-30.0, 30.0), clearance_m: float = 0.3) -> tuple[Camera, ...]:
    """The input camera turned by each angle of ``degrees`` about the vertical axis through the
    room's objects (the median of their box centres), still looking the same way at them: the
    second and third viewpoints of the novel-view bench. Where the turned camera would leave the
    room (``clearance_m`` from its rectangle) or stand within ``clearance_m`` of an object's
    box, it is moved towards the pivot (down to half its distance) until it does not. Pure numpy."""
    cam = spec.camera
    pivot = np.median(np.array([o.position_m for o in spec.objects]), axis=0) if spec.objects else cam.position_m
    lx, ly, _ = spec.room_size_m
    out = []
    for deg in degrees:
        rot = frames.rot_z(np.radians(deg))
        offset = rot[:2, :2] @ (cam.position_m[:2] - pivot[:2])
        chosen = None
        for scale in (1.0, 0.9, 0.8, 0.7, 0.6, 0.5):
            xy = pivot[:2] + scale * offset
            inside = clearance_m <= xy[0] <= lx - clearance_m and clearance_m <= xy[1] <= ly - clearance_m
            clear = all(np.linalg.norm(xy - np.asarray(o.position_m[:2])) > np.hypot(o.size_m[0], o.size_m[1]) / 2 + clearance_m for o in spec.objects)
            if inside and clear:
                chosen = xy
                break
        xy = pivot[:2] + 0.5 * offset if chosen is None else chosen
        t = frames.pose(rot @ cam.world_from_camera[:3, :3], [xy[0], xy[1], cam.position_m[2]])
        out.append(Camera(cam.intrinsics, t))
    return tuple(out)


def corrupt_depth(depth_m: np.ndarray, noise: DepthNoise, seed: int) -> np.ndarray:
    """(H, W) float32 depth with sensor-like noise, holes and edge dropouts (0 = invalid)."""
    rng = np.random.default_rng([seed, 7])
    d = depth_m.astype(np.float64)
    valid = d > 0
    out = d + rng.normal(size=d.shape) * noise.rel_sigma * d
    h, w = d.shape
    # Dropouts at depth discontinuities (flying pixels / shadowing of structured-light sensors).
    jump = np.zeros_like(valid)
    dx = np.abs(np.diff(d, axis=1)) > 0.05
    dy = np.abs(np.diff(d, axis=0)) > 0.05
    jump[:, 1:] |= dx
    jump[:, :-1] |= dx
    jump[1:, :] |= dy
    jump[:-1, :] |= dy
    drop = jump & (rng.random(d.shape) < noise.edge_dropout)
    # Random elliptical holes (specular or dark surfaces).
    vv, uu = np.mgrid[0:h, 0:w]
    for _ in range(noise.holes):
        cu, cv = rng.uniform(0, w), rng.uniform(0, h)
        au, av = rng.uniform(5, 30), rng.uniform(5, 30)
        drop |= ((uu - cu) / au) ** 2 + ((vv - cv) / av) ** 2 < 1.0
    out[~valid | drop | (out > noise.max_range_m) | (out <= 0)] = 0.0
    return out.astype(np.float32)


def _depth_png(depth_m: np.ndarray) -> np.ndarray:
    return np.clip(np.round(depth_m.astype(np.float64) * 1000.0), 0, 65535).astype(np.uint16)


def ground_truth(spec: RoomSpec, instances: np.ndarray | None = None) -> dict:
    """The ``ground_truth`` block of ``meta.json`` (JSON-ready)."""
    k = spec.camera.intrinsics
    visible = np.bincount(instances.ravel(), minlength=len(spec.objects) + 1) if instances is not None else None
    objs = []
    for o in spec.objects:
        objs.append(
            {
                "object_id": o.object_id,
                "name": o.name,
                "category": o.category,
                "kind": o.kind.value,
                "position_m": list(o.position_m),
                "size_m": list(o.size_m),
                "yaw_rad": o.yaw_rad,
                "world_from_object": o.world_from_object.tolist(),
                "support": o.support,
                "mass_kg": o.mass_kg,
                "density_kg_m3": DENSITY_KG_M3[o.category],
                "visible_px": int(visible[o.object_id]) if visible is not None else None,
                "parts": sorted({p.body or "body" for p in o.primitives}),
                "joints": [
                    {"part": j.part, "type": j.type, "axis": list(j.axis), "anchor_m": list(j.anchor_m), "lower": j.lower, "upper": j.upper}
                    for j in o.joints
                ],
            }
        )
    return {
        "frame": "world: right-handed, Z up, floor z = 0, metres",
        "box_convention": (
            "position_m = centre of the gravity-aligned bounding box in the world; size_m = full extents (x, y, z) "
            "in the object frame (x = depth, front faces +X; y = width; z = height); yaw_rad = rotation of the object "
            "frame about world +Z; world_from_object = pose of the object frame, origin at the bottom-face centre"
        ),
        "camera": {
            "intrinsics": {"fx": k.fx_px, "fy": k.fy_px, "cx": k.cx_px, "cy": k.cy_px, "width": k.width_px, "height": k.height_px},
            "world_from_camera": spec.camera.world_from_camera.tolist(),
            "convention": "OpenCV camera (x right, y down, z forward)",
        },
        "room_size_m": list(spec.room_size_m),
        "floor": {"normal": [0.0, 0.0, 1.0], "offset_m": 0.0},
        "walls": [{"name": w.name, "normal": list(w.normal), "offset_m": w.offset_m} for w in spec.walls],
        "objects": objs,
        "support_graph": [[o.name, o.support] for o in spec.objects],
        "instances": "instances.png",
        "metric_depth": "depth_gt.png" if spec.noise is not None else "depth.png",
        "boxes_3d": None,
    }


def render_room(spec: RoomSpec, out_dir: Path) -> Path:
    """Render ``spec`` and write the sample folder ``out_dir`` (created); returns ``out_dir``.

    Files: rgb.png, depth.png (uint16 mm, 0 invalid; noisy when ``spec.noise``), depth_gt.png
    (clean, only with noise), instances.png (uint16 object ids), camera.json, meta.json.
    """
    from PIL import Image

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    r = render_arrays(spec)
    depth = r.depth_m if spec.noise is None else corrupt_depth(r.depth_m, spec.noise, spec.seed)
    Image.fromarray(r.rgb).save(out_dir / "rgb.png", compress_level=1)
    Image.fromarray(_depth_png(depth)).save(out_dir / "depth.png", compress_level=1)
    if spec.noise is not None:
        Image.fromarray(_depth_png(r.depth_m)).save(out_dir / "depth_gt.png", compress_level=1)
    Image.fromarray(r.instances).save(out_dir / "instances.png", compress_level=1)
    k = spec.camera.intrinsics
    cam = {"fx": k.fx_px, "fy": k.fy_px, "cx": k.cx_px, "cy": k.cy_px, "width": k.width_px, "height": k.height_px}
    (out_dir / "camera.json").write_text(json.dumps(cam, indent=1) + "\n")
    noise = None if spec.noise is None else {
        "model": "depth-proportional Gaussian, elliptical holes, dropouts at depth edges, mm quantisation",
        "rel_sigma": spec.noise.rel_sigma,
        "holes": spec.noise.holes,
        "edge_dropout": spec.noise.edge_dropout,
        "max_range_m": spec.noise.max_range_m,
    }
    meta = {
        "name": spec.name,
        "source_repo": "scene-builder (scene_builder.bench.procedural)",
        "dataset": "procedural room rendered with MuJoCo",
        "synthetic": True,
        "seed": spec.seed,
        "rgb_file": "rgb.png",
        "rgb_size": [k.width_px, k.height_px],
        "depth_file": "depth.png",
        "depth_units": "uint16 millimetres, 0 = invalid (depth_m = png / 1000)",
        "depth_aligned_to_rgb": True,
        "depth_size": [k.width_px, k.height_px],
        "depth_valid_fraction": round(float((depth > 0).mean()), 4),
        "depth_note": "MuJoCo planar z-depth" + (", corrupted like a sensor (see depth_noise)" if noise else ", exact up to mm quantisation"),
        "depth_noise": noise,
        "intrinsics_status": "given",
        "intrinsics_assumed": False,
        "intrinsics_note": "the render camera (Kinect-like pinhole)",
        "ground_truth": ground_truth(spec, r.instances),
    }
    (out_dir / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    return out_dir


def write_demo_input(out_dir: Path, seed: int = 0, n_objects: int = 6) -> Path:
    """Render the demo room (clean depth) into ``out_dir``; returns the folder, ready for
    ``scene_builder.pipeline.build`` (``rgb.png`` + ``depth.png`` + ``camera.json``)."""
    return render_room(make_room(seed, n_objects=n_objects, noise=False), Path(out_dir))
