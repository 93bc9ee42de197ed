"""Exact JSON round trip of the data model (``scene.json``).

Any dataclass of :mod:`scene_builder.model` serialises to plain JSON and back to an equal value:

* floats are written with ``repr`` precision (Python's JSON does), so they round-trip bit for bit;
* numpy arrays become ``{"dtype", "shape", "data"}`` with ``data`` a flat list for small arrays
  (readable) or base64 of the little-endian bytes for large ones (compact and exact);
* enums become their value; tuples become lists; nested dataclasses become objects with a
  ``"__type__"`` key naming the class;
* a :class:`~scene_builder.model.Texture` is stored once per name as a PNG (lossless, so the
  round trip is exact; deterministic bytes for the same image), and later uses of the same
  texture refer to it by name (``{"__texture__": name}``).
"""

from __future__ import annotations

import base64
import dataclasses
import enum
import json
import typing
from pathlib import Path

import numpy as np

from scene_builder import model

_SMALL_ARRAY = 16
_TYPES: dict[str, type] = {
    name: getattr(model, name) for name in model.__all__ if dataclasses.is_dataclass(getattr(model, name, None))
}
FORMAT_VERSION = 1


def _png_base64(image_rgb: np.ndarray) -> str:
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image_rgb)).save(buf, format="PNG", compress_level=6)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _image_from_png_base64(data: str) -> np.ndarray:
    import io

    from PIL import Image

    try:
        with Image.open(io.BytesIO(base64.b64decode(data, validate=True))) as im:
            return np.array(im.convert("RGB"))
    except Exception as err:  # PIL raises several types for corrupt data; report one
        raise ValueError(f"scene.json: a texture is not a readable PNG ({type(err).__name__})") from err


def to_jsonable(value, _textures: dict[str, int] | None = None):
    """Convert a model value (dataclass, array, enum, tuple, scalar) to JSON-compatible data."""
    if _textures is None:
        _textures = {}
    if isinstance(value, model.Texture):
        if value.name in _textures:
            if _textures[value.name] != id(value):
                raise ValueError(f"two different textures are named {value.name!r}; texture names must be unique")
            return {"__texture__": value.name}
        _textures[value.name] = id(value)
        return {"__type__": "Texture", "name": value.name, "png_base64": _png_base64(value.image_rgb)}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out = {"__type__": type(value).__name__}
        for f in dataclasses.fields(value):
            out[f.name] = to_jsonable(getattr(value, f.name), _textures)
        return out
    if isinstance(value, np.ndarray):
        arr = np.ascontiguousarray(value)
        if arr.size <= _SMALL_ARRAY and arr.dtype.kind in "fiub":
            data = arr.ravel().tolist()
        else:
            data = base64.b64encode(arr.astype(arr.dtype.newbyteorder("<")).tobytes()).decode("ascii")
        return {"__ndarray__": True, "dtype": arr.dtype.str.lstrip("<>|="), "shape": list(arr.shape), "data": data}
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, (tuple, list)):
        return [to_jsonable(v, _textures) for v in value]
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise TypeError(f"cannot serialise {type(value).__name__}")


def _decode_array(obj: dict) -> np.ndarray:
    dtype = np.dtype(obj["dtype"]).newbyteorder("<") if np.dtype(obj["dtype"]).itemsize > 1 else np.dtype(obj["dtype"])
    shape = tuple(obj["shape"])
    data = obj["data"]
    if isinstance(data, str):
        arr = np.frombuffer(base64.b64decode(data), dtype=dtype).reshape(shape)
    else:
        arr = np.array(data, dtype=dtype).reshape(shape)
    return arr.astype(np.dtype(obj["dtype"]), copy=True)


def _from(value, hint, textures: dict[str, "model.Texture"]):
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if value is None:
        return None
    if isinstance(value, dict) and value.get("__ndarray__"):
        return _decode_array(value)
    if isinstance(value, dict) and "__texture__" in value:
        name = value["__texture__"]
        if name not in textures:
            raise ValueError(f"scene.json: texture {name!r} is used before it is defined")
        return textures[name]
    if isinstance(value, dict) and "__type__" in value:
        return from_jsonable(value, textures)
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        non_none = [a for a in args if a is not type(None)]
        return _from(value, non_none[0], textures) if len(non_none) == 1 else value
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_from(v, args[0], textures) for v in value)
        if args:
            return tuple(_from(v, a, textures) for v, a in zip(value, args))
        return tuple(value)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return hint(value)
    if hint is float and isinstance(value, int):
        return float(value)
    if hint is Path:
        return Path(value)
    return value


def from_jsonable(obj: dict, _textures: dict[str, "model.Texture"] | None = None):
    """Inverse of :func:`to_jsonable` for a dataclass object."""
    textures = {} if _textures is None else _textures
    cls = _TYPES.get(obj.get("__type__", ""))
    if cls is None:
        raise ValueError(f"scene.json: unknown type {obj.get('__type__')!r}")
    if cls is model.Texture:
        texture = model.Texture(str(obj["name"]), _image_from_png_base64(obj["png_base64"]))
        textures[texture.name] = texture
        return texture
    hints = typing.get_type_hints(cls)
    kwargs = {f.name: _from(obj[f.name], hints[f.name], textures) for f in dataclasses.fields(cls) if f.name in obj}
    return cls(**kwargs)


def scene_to_json(scene: model.Scene) -> str:
    """Serialise a Scene to the text of ``scene.json`` (deterministic: sorted keys, no timestamps)."""
    return json.dumps({"format": "scene-builder/scene", "version": FORMAT_VERSION, "scene": to_jsonable(scene)}, sort_keys=True)


def scene_from_json(text: str) -> model.Scene:
    """Parse the text of ``scene.json``. Raises ValueError with a one-line reason on malformed input."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as err:
        raise ValueError(f"scene.json is not valid JSON ({err.msg} at line {err.lineno})") from err
    if not isinstance(doc, dict) or doc.get("format") != "scene-builder/scene":
        raise ValueError("scene.json: not a scene-builder scene file")
    if doc.get("version") != FORMAT_VERSION:
        raise ValueError(f"scene.json: version {doc.get('version')} is not supported (expected {FORMAT_VERSION})")
    scene = from_jsonable(doc["scene"])
    if not isinstance(scene, model.Scene):
        raise ValueError("scene.json: top-level value is not a Scene")
    return scene
