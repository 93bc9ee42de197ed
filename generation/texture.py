"""Photo textures for generated assets: the photo projected onto each asset from the input camera.

The visible surfaces of an object carry the photo's colours, as a texture projected from the
camera that took it: each visual-mesh vertex, placed at the pose where the object was seen
(``GeneratedAsset.world_from_asset``), projects to a pixel, and that pixel's position in a crop
of the photo around the object's mask is the vertex's texture coordinate. Hidden surfaces
project into the same silhouette (the back of a box lands on its front), or onto pixels of
whatever hides them: the crop's pixels outside the object's mask are replaced by the colour of
the nearest mask pixel, so hidden surfaces get a plausible fill from the object's own visible
colours. The texture moves with the object (the coordinates are fixed at the observed pose).

The crop keeps the photo's full resolution (``Observation.photo_rgb``, the stored photo when
perception analysed a downscaled copy).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scene_builder.frames import transform_points
from scene_builder.model import Camera, GeneratedAsset, Observation, PerceivedObject, Texture

__all__ = ["CROP_MARGIN_PX", "object_texture", "photo_textured"]

#: The crop reaches this many pixels past the mask's bounding box (texture filtering reads a
#: little around each texel).
CROP_MARGIN_PX = 4


def object_texture(rgb: np.ndarray, mask: np.ndarray, name: str) -> tuple[Texture, tuple[int, int]]:
    """The texture of one object: the (h, w, 3) crop of ``rgb`` around ``mask`` ((H, W) bool),
    pixels outside the mask (eroded by one pixel: edge pixels mix in the background) replaced by
    the nearest mask pixel's colour. Returns the texture and the crop's top-left (row, column)."""
    from scipy import ndimage

    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        raise ValueError(f"object {name}: empty mask, nothing to texture")
    h, w = mask.shape
    r0, r1 = max(0, rows[0] - CROP_MARGIN_PX), min(h, rows[-1] + 1 + CROP_MARGIN_PX)
    c0, c1 = max(0, cols[0] - CROP_MARGIN_PX), min(w, cols[-1] + 1 + CROP_MARGIN_PX)
    crop = np.array(rgb[r0:r1, c0:c1])
    m = mask[r0:r1, c0:c1]
    core = ndimage.binary_erosion(m)
    source = core if core.sum() >= max(4, 0.25 * m.sum()) else m
    # The nearest source pixel of every pixel (a Euclidean distance transform's indices).
    _, (ri, ci) = ndimage.distance_transform_edt(~source, return_indices=True)
    filled = crop[ri, ci]
    return Texture(name, filled), (int(r0), int(c0))


def photo_textured(generated: GeneratedAsset, obj: PerceivedObject, observation: Observation, camera: Camera) -> GeneratedAsset:
    """``generated`` with every visual mesh of its asset textured with the photo (see the module
    docstring). Deformables keep their colours (a MuJoCo flex carries no texture)."""
    photo = observation.photo_rgb  # full resolution when the analysis ran downscaled
    mask = obj.mask
    scale = photo.shape[1] / observation.rgb.shape[1]
    if photo.shape[:2] != observation.rgb.shape[:2]:
        import cv2

        mask = cv2.resize(mask.astype(np.uint8), (photo.shape[1], photo.shape[0]), interpolation=cv2.INTER_NEAREST) > 0
    texture, (r0, c0) = object_texture(photo, mask, generated.asset.name)
    th, tw = texture.image_rgb.shape[:2]
    k = camera.intrinsics.scaled(photo.shape[1], photo.shape[0]) if scale != 1.0 else camera.intrinsics
    camera_from_asset = np.linalg.inv(camera.world_from_camera) @ generated.world_from_asset
    parts = []
    for part in generated.asset.parts:
        p = transform_points(camera_from_asset, part.visual.vertices_m)
        z = np.maximum(p[:, 2], 1e-3)
        x = k.fx_px * p[:, 0] / z + k.cx_px
        y = k.fy_px * p[:, 1] / z + k.cy_px
        uv = np.stack([(x - c0 + 0.5) / tw, (y - r0 + 0.5) / th], axis=1)
        visual = dataclasses.replace(part.visual, uv=np.clip(uv, 0.0, 1.0), texture=texture)
        parts.append(dataclasses.replace(part, visual=visual))
    asset = dataclasses.replace(generated.asset, parts=tuple(parts))
    return dataclasses.replace(generated, asset=asset)
