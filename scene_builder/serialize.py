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
import binascii
import dataclasses
import enum
import json
import math
import types
import typing
from pathlib import Path

import numpy as np

from scene_builder import model
from scene_builder.errors import PIL_READ_ERRORS, InputError


class SceneFileError(InputError, ValueError):
    """A ``scene.json`` that cannot be read: the one-line message names the field."""

_SMALL_ARRAY = 16
_TYPES: dict[str, type] = {
    name: getattr(model, name) for name in model.__all__ if dataclasses.is_dataclass(getattr(model, name, None))
}
FORMAT_VERSION = 1


def _image_from_png_base64(data: str) -> np.ndarray:
    import io

    from PIL import Image

    try:
        png = base64.b64decode(data, validate=True)
    except binascii.Error as err:  # a ValueError: what b64decode documents
        raise ValueError(f"scene.json: a texture is not base64 ({err})") from err
    try:
        with Image.open(io.BytesIO(png)) as im:
            return np.array(im.convert("RGB"))
    except PIL_READ_ERRORS as err:  # what Pillow raises for bytes it cannot read
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
        return {"__type__": "Texture", "name": value.name, "png_base64": base64.b64encode(value.png_bytes).decode("ascii")}
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


#: numpy dtype kinds a scene file may hold: bool, signed / unsigned integers, floats.
_ARRAY_KINDS = "biuf"


def _decode_array(obj: dict, where: str) -> np.ndarray:
    try:
        if not isinstance(obj.get("dtype"), str) or len(obj["dtype"]) > 8:
            raise ValueError("not a short dtype name")
        want = np.dtype(obj["dtype"])
    except (TypeError, ValueError, KeyError, SyntaxError) as err:
        raise SceneFileError(f"scene.json: {where}: array dtype {str(obj.get('dtype'))[:20]!r} is not a numpy dtype") from err
    if want.kind not in _ARRAY_KINDS or want.itemsize > 8:
        raise SceneFileError(f"scene.json: {where}: array dtype {want} is not a number type")
    shape = obj.get("shape")
    if not isinstance(shape, list) or not all(isinstance(n, int) and not isinstance(n, bool) and 0 <= n < 2**31 for n in shape) or len(shape) > 8:
        raise SceneFileError(f"scene.json: {where}: array shape {str(shape)[:40]} is not a list of sizes")
    count = math.prod(shape)
    data = obj.get("data")
    le = want.newbyteorder("<") if want.itemsize > 1 else want
    if isinstance(data, str):
        if len(data) > 4 * (count * want.itemsize + 2) // 3 + 4:
            raise SceneFileError(f"scene.json: {where}: array data is longer than its shape {shape} needs")
        try:
            raw = base64.b64decode(data, validate=True)
        except ValueError as err:  # binascii.Error
            raise SceneFileError(f"scene.json: {where}: array data is not base64 ({err})") from err
        if len(raw) != count * want.itemsize:
            raise SceneFileError(f"scene.json: {where}: array data holds {len(raw)} bytes, shape {shape} of {want} needs {count * want.itemsize}")
        arr = np.frombuffer(raw, dtype=le).reshape(shape)
    elif isinstance(data, list):
        if len(data) != count or not all(isinstance(v, (int, float)) for v in data):
            raise SceneFileError(f"scene.json: {where}: array data is not {count} numbers")
        try:
            arr = np.array(data, dtype=want).reshape(shape)
        except (OverflowError, ValueError) as err:  # -1 for a uint8, 1e300 for an int32
            raise SceneFileError(f"scene.json: {where}: array data does not fit {want} ({err})") from err
    else:
        raise SceneFileError(f"scene.json: {where}: array data must be a list or base64 text")
    return arr.astype(want, copy=True)


def _from(value, hint, where: str, textures: dict[str, "model.Texture"]):
    """The model value of JSON ``value`` for a field annotated ``hint``; SceneFileError when it
    does not fit. Unknown annotations pass the value through. ``textures``: the textures defined
    so far (each is written once, then referred to by name)."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        non_none = [a for a in args if a is not type(None)]
        if len(non_none) == 1:
            return _from(value, non_none[0], where, textures)
        return value
    if value is None:
        raise SceneFileError(f"scene.json: {where} is null")
    if hint is np.ndarray:
        if not (isinstance(value, dict) and value.get("__ndarray__") is True):
            raise SceneFileError(f"scene.json: {where} must be an array object")
        return _decode_array(value, where)
    if hint is model.Texture and isinstance(value, dict) and "__texture__" in value:
        name = value["__texture__"]
        if not isinstance(name, str) or name not in textures:
            raise SceneFileError(f"scene.json: {where}: texture {str(name)[:30]!r} is used before it is defined")
        return textures[name]
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        if not (isinstance(value, dict) and value.get("__type__") == hint.__name__):
            raise SceneFileError(f"scene.json: {where} must be a {hint.__name__} object")
        return _from_object(value, where, textures)
    if origin is tuple:
        if not isinstance(value, list):
            raise SceneFileError(f"scene.json: {where} must be a list")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_from(v, args[0], f"{where}[{i}]", textures) for i, v in enumerate(value))
        if args:
            if len(value) != len(args):
                raise SceneFileError(f"scene.json: {where} must have {len(args)} items, has {len(value)}")
            return tuple(_from(v, a, f"{where}[{i}]", textures) for i, (v, a) in enumerate(zip(value, args)))
        return tuple(value)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        try:
            return hint(value)
        except ValueError as err:
            raise SceneFileError(f"scene.json: {where}: {str(value)[:20]!r} is not a {hint.__name__}") from err
    if hint is bool:
        if not isinstance(value, bool):
            raise SceneFileError(f"scene.json: {where} must be true or false")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneFileError(f"scene.json: {where} must be an integer")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneFileError(f"scene.json: {where} must be a number")
        return float(value)
    if hint is str or hint is Path:
        if not isinstance(value, str):
            raise SceneFileError(f"scene.json: {where} must be text")
        return Path(value) if hint is Path else value
    return value


def _from_object(obj: dict, where: str, textures: dict[str, "model.Texture"]):
    cls = _TYPES.get(obj.get("__type__", "")) if isinstance(obj.get("__type__"), str) else None
    if cls is None:
        raise SceneFileError(f"scene.json: {where}: unknown type {str(obj.get('__type__'))[:30]!r}")
    if cls is model.Texture:
        name, data = obj.get("name"), obj.get("png_base64")
        if not (isinstance(name, str) and isinstance(data, str)):
            raise SceneFileError(f"scene.json: {where}: a Texture needs a text 'name' and 'png_base64'")
        try:
            texture = model.Texture(name, _image_from_png_base64(data))
        except ValueError as err:
            raise SceneFileError(f"scene.json: {where}: {' '.join(str(err).split())[:160]}") from err
        textures[texture.name] = texture
        return texture
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name in obj:
            kwargs[f.name] = _from(obj[f.name], hints[f.name], f"{where}.{f.name}", textures)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise SceneFileError(f"scene.json: {where}: {cls.__name__} has no {f.name!r}")
    try:
        return cls(**kwargs)
    except (ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError) as err:  # the model's own checks
        raise SceneFileError(f"scene.json: {where}: {' '.join(str(err).split())[:160]}") from err


def from_jsonable(obj: dict, _textures: dict[str, "model.Texture"] | None = None):
    """Inverse of :func:`to_jsonable` for a dataclass object. Raises SceneFileError (a
    ValueError) naming the field when ``obj`` does not describe a valid model value."""
    if not isinstance(obj, dict):
        raise SceneFileError("scene.json: expected an object")
    return _from_object(obj, str(obj.get("__type__", "value")), {} if _textures is None else _textures)


def scene_to_json(scene: model.Scene) -> str:
    """Serialise a Scene to the text of ``scene.json`` (deterministic: sorted keys, no timestamps)."""
    return json.dumps({"format": "scene-builder/scene", "version": FORMAT_VERSION, "scene": to_jsonable(scene)}, sort_keys=True)


def scene_from_json(text: str | bytes) -> model.Scene:
    """Parse the text of ``scene.json``. Raises SceneFileError (an InputError and a ValueError)
    with a one-line reason, naming the field, on any malformed input; never anything else."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as err:
        raise SceneFileError(f"scene.json is not valid JSON ({err.msg} at line {err.lineno})") from err
    except (UnicodeDecodeError, RecursionError, ValueError, TypeError) as err:
        raise SceneFileError(f"scene.json cannot be read as JSON ({type(err).__name__})") from err
    if not isinstance(doc, dict) or doc.get("format") != "scene-builder/scene":
        raise SceneFileError("scene.json: not a scene-builder scene file")
    if doc.get("version") != FORMAT_VERSION:
        raise SceneFileError(f"scene.json: version {str(doc.get('version'))[:10]} is not supported (expected {FORMAT_VERSION})")
    if not (isinstance(doc.get("scene"), dict) and doc["scene"].get("__type__") == "Scene"):
        raise SceneFileError("scene.json: top-level value is not a Scene")
    try:
        return from_jsonable(doc["scene"])
    except RecursionError as err:
        raise SceneFileError("scene.json: nested too deeply") from err
