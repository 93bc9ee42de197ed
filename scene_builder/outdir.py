"""The output folder: the marker that says scene-builder wrote it, and the rules for writing and
replacing it ("never destroy what you did not create").

A build writes into a hidden staging folder beside OUT (:func:`make_staging`), writes the marker
:data:`MARKER` last (:func:`write_marker`: the input image, every folder and every file written
with its size and SHA-256) and renames the staging folder into place (:func:`move_into_place`).

An existing OUT (:func:`check_out_dir`) is replaced only when it is empty or scene-builder wrote
it (its marker beside ``report.json``), and then

* without ``overwrite``: only when nothing under it was added or changed since (every file and
  folder is one the marker records, every file hashes as recorded); else the error names them;
* with ``overwrite``: edited or not. A folder scene-builder did not write is never replaced,
  ``overwrite`` or not.

A marker of an older scene-builder (version 1: top-level names, no hashes) cannot show edits, so
such a folder is replaced only with ``overwrite``. A symbolic link given as OUT is followed: the
folder it points to is checked and replaced, the link kept (:func:`real_out_dir`). The contents
are checked again after the old folder is set aside and before it is deleted, so a file added
during a build is never lost.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from scene_builder.config import InputSpec
from scene_builder.errors import ExportError, InputError, InputWarning

#: Marker file a build writes into its output folder: JSON naming the input image, every folder
#: and every file the build wrote (with size and SHA-256), so that a later build knows the folder
#: is its own and whether anything in it was added or changed since.
MARKER = ".scene-builder"
_MARKER_FORMAT = "scene-builder/output"
#: Version 2 records hashes; version 1 (older builds) only the top-level names.
MARKER_VERSION = 2


@dataclass(frozen=True)
class Changes:
    """What is under an output folder that its marker does not account for (paths relative to
    the folder, ``/``-separated, sorted)."""

    added: tuple[str, ...] = ()
    changed: tuple[str, ...] = ()

    def __bool__(self) -> bool:
        return bool(self.added or self.changed)

    def describe(self, limit: int = 3) -> str:
        parts = []
        for what, names in (("added", self.added), ("changed", self.changed)):
            if names:
                more = f" and {len(names) - limit} more" if len(names) > limit else ""
                parts.append(f"{what}: {', '.join(names[:limit])}{more}")
        return "; ".join(parts)


def _is_within(path: Path, folder: Path) -> bool:
    """``path`` is ``folder`` or lies inside it (both resolved)."""
    return path == folder or folder in path.parents


def _sha256(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def _entries(folder: Path) -> tuple[list[str], list[str], list[str]]:
    """(folders, regular files, anything else: links, sockets, ...) under ``folder``, relative,
    ``/``-separated, without :data:`MARKER` at the top. Links are listed, never followed."""
    folders, files, other = [], [], []
    stack = [(Path(folder), "")]
    while stack:
        here, prefix = stack.pop()
        with os.scandir(here) as it:
            for e in it:
                rel = prefix + e.name
                if rel == MARKER:
                    continue
                if e.is_dir(follow_symlinks=False):
                    folders.append(rel)
                    stack.append((Path(e.path), rel + "/"))
                elif e.is_file(follow_symlinks=False):
                    files.append(rel)
                else:
                    other.append(rel)
    return sorted(folders), sorted(files), sorted(other)


def read_marker(folder: Path) -> dict | None:
    """The marker of an output folder scene-builder wrote, or None (no marker, unreadable or
    malformed marker, or no ``report.json`` beside it)."""
    try:
        doc = json.loads((Path(folder) / MARKER).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("format") != _MARKER_FORMAT or not isinstance(doc.get("files"), list):
        return None
    hashes = doc.get("hashes")
    if hashes is not None and not (
        isinstance(hashes, dict)
        and all(isinstance(v, dict) and isinstance(v.get("sha256"), str) and isinstance(v.get("bytes"), int) for v in hashes.values())
        and isinstance(doc.get("folders"), list)
    ):
        return None
    if not (Path(folder) / "report.json").is_file():
        return None
    return doc


def _record(folder: Path, rel: str) -> dict:
    path = folder / rel
    return {"bytes": path.stat().st_size, "sha256": _sha256(path)}


def write_marker(folder: Path, inputs: InputSpec) -> Path:
    """Write :data:`MARKER` in ``folder`` (a build's staging folder, once everything else is
    written): the input image, the top-level names, every folder, and every file with its size
    and SHA-256 (read once here; a later build hashes the folder again to compare)."""
    folder = Path(folder)
    folders, files, other = _entries(folder)
    if other:  # scene-builder writes folders and plain files only
        raise ExportError(f"the build wrote {folder / other[0]}, which is neither a file nor a folder; its output cannot be recorded")
    doc = {
        "format": _MARKER_FORMAT,
        "version": MARKER_VERSION,
        "image": str(Path(inputs.image_path).resolve()),
        "files": sorted(p.name for p in folder.iterdir() if p.name != MARKER),
        "folders": folders,
        "hashes": {rel: _record(folder, rel) for rel in files},
    }
    return _write_doc(folder, doc)


def _write_doc(folder: Path, doc: dict) -> Path:
    return replace_file(folder, MARKER, json.dumps(doc, indent=2) + "\n")


def replace_file(folder: Path, name: str, text: str) -> Path:
    """Write ``folder/name`` whole or not at all: a hidden temporary file beside it, renamed over
    it (removed again when anything fails); the permissions the umask allows."""
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", dir=folder)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, Path(folder) / name)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return Path(folder) / name


def add_to_marker(folder: Path, name: str) -> None:
    """Record that scene-builder also wrote the file ``folder/name`` after the build (the demo's
    comparison, ``interaction.json``)."""
    folder = Path(folder)
    doc = read_marker(folder)
    if doc is None:
        raise InputError(f"{folder} is not an output folder of scene-builder (no {MARKER}); cannot add {name} to it")
    doc["files"] = sorted(set(doc["files"]) | {name.split("/")[0]})
    if doc.get("hashes") is not None:
        doc["hashes"][name] = _record(folder, name)
    _write_doc(folder, doc)


def owns_file(folder: Path, name: str) -> bool:
    """Whether scene-builder may write ``folder/name``: the folder is a build of scene-builder and
    the file is absent, or recorded in the marker and unchanged since."""
    doc = read_marker(folder)
    if doc is None:
        return False
    path = Path(folder) / name
    if not path.exists() and not path.is_symlink():
        return True
    entry = (doc.get("hashes") or {}).get(name)
    return entry is not None and path.is_file() and not path.is_symlink() and _unchanged(path, entry)


def _unchanged(path: Path, entry: dict) -> bool:
    try:
        return path.stat().st_size == entry["bytes"] and _sha256(path) == entry["sha256"]
    except OSError:  # unreadable now: it cannot be shown to be the file written
        return False


def changes(folder: Path, marker: dict) -> Changes:
    """What under ``folder`` its (version 2) marker does not account for: entries it does not
    record (added) and files whose size or SHA-256 differ (changed). Files the marker records
    that are gone are no loss and not listed."""
    folder = Path(folder)
    folders, files, other = _entries(folder)
    hashes, known_folders = marker["hashes"], set(marker["folders"])
    added = [f for f in folders if f not in known_folders] + [f for f in files if f not in hashes] + other
    changed = [f for f in files if f in hashes and not _unchanged(folder / f, hashes[f])]
    return Changes(tuple(sorted(added)), tuple(changed))


def real_out_dir(out_dir: Path) -> Path:
    """The folder a build writes: ``out_dir``, or where it points when it is a symbolic link (the
    link is kept and points at the new output)."""
    out_dir = Path(out_dir)
    return out_dir.resolve() if out_dir.is_symlink() else out_dir


def check_location(out_dir: Path, inputs: InputSpec | None = None) -> None:
    """Raise InputError (one line) when ``out_dir`` may never be written: a file; the current
    folder or one that contains it; a folder that holds an input file; a folder inside the
    image's folder unless that is the current folder (``-o`` into a dataset's sample folder;
    running in the photo's own folder is fine); a parent that does not exist or is not
    writable."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"output path {out_dir} is a file; pass -o with a folder name")
    target = out_dir.resolve()
    cwd = Path.cwd().resolve()
    if _is_within(cwd, target):
        raise InputError(f"output folder {out_dir} is the current folder or contains it, and would be replaced; pass -o with a new folder name")
    if inputs is not None:
        given = [Path(p) for p in (inputs.image_path, inputs.depth_path) if p is not None]
        for p in given:
            if _is_within(p.resolve(), target):
                raise InputError(f"output folder {out_dir} holds the input {p} and would be replaced; pass -o with a folder outside it")
        image_dir = Path(inputs.image_path).resolve().parent
        if image_dir != cwd and _is_within(target, image_dir):
            raise InputError(
                f"output folder {out_dir} is inside the input's folder {image_dir}; pass -o with a folder outside it "
                "(or run scene-builder from that folder)"
            )
    parent = target.parent
    if not parent.is_dir():
        raise InputError(f"output folder's parent {out_dir.parent} does not exist; create it or choose another -o")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"cannot write in {out_dir.parent} (permission denied); choose another -o")


def check_replaceable(
    folder: Path, inputs: InputSpec | None = None, overwrite: bool = False, default_name: bool = False, shown: Path | None = None
) -> None:
    """Raise InputError (one line) unless the existing folder ``folder`` may be replaced (see the
    module's docstring); ``shown`` is the name the user gave it (default ``folder``)."""
    folder = Path(folder)
    shown = folder if shown is None else shown
    if not any(folder.iterdir()):
        return  # an empty folder holds nothing to lose
    marker = read_marker(folder)
    if marker is None:
        raise InputError(
            f"output folder {shown} exists and was not written by scene-builder (no {MARKER} beside report.json); "
            "it is never replaced, even with --overwrite: choose another -o, or move it away yourself"
        )
    if overwrite:
        return
    if marker.get("hashes") is None:
        raise InputError(
            f"output folder {shown} was written by an older scene-builder whose marker records no file hashes, so changes "
            "to it cannot be seen; pass --overwrite to replace it, or choose another -o"
        )
    found = changes(folder, marker)
    if found:
        raise InputError(
            f"output folder {shown} holds files added or changed since scene-builder wrote it ({found.describe()}); "
            "move them, choose another -o, or pass --overwrite to replace the folder with them"
        )
    if default_name and inputs is not None and marker.get("image") != str(Path(inputs.image_path).resolve()):
        raise InputError(
            f"{shown} holds the build of another image ({marker.get('image')}); pass -o NAME "
            f"(e.g. -o {Path(inputs.image_path).resolve().parent.name}_{Path(shown).name}) or --overwrite"
        )


def check_out_dir(out_dir: Path, inputs: InputSpec | None = None, overwrite: bool = False, default_name: bool = False) -> None:
    """Raise InputError (one line) unless ``out_dir`` may be written (:func:`check_location`) and,
    when it exists, replaced (:func:`check_replaceable`); under ``default_name`` only by a build
    of the same image."""
    check_location(out_dir, inputs)
    if Path(out_dir).exists():
        check_replaceable(real_out_dir(out_dir), inputs, overwrite, default_name, shown=Path(out_dir))


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def make_staging(out_dir: Path) -> Path:
    """A hidden staging folder beside ``out_dir`` with the permissions the umask allows
    (``tempfile.mkdtemp`` makes it 0700, which would keep other users and containers out)."""
    try:
        staging = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=out_dir.parent))
    except OSError as err:
        raise InputError(f"cannot create the output folder beside {out_dir} ({err.strerror}); choose another -o") from err
    staging.chmod(0o777 & ~_umask())
    return staging


def move_into_place(staging: Path, out_dir: Path, verify: Callable[[Path], None] | None = None) -> None:
    """Replace the folder ``out_dir`` (not a link: see :func:`real_out_dir`) with ``staging``.
    Renames on one filesystem: the old folder is set aside, ``verify(set_aside)`` runs on it (it
    raises to keep it: the old folder is put back), the new one is renamed into place, and only
    then the old one is deleted. A failure to delete it is a warning naming what is left."""
    old = None
    if out_dir.exists():
        old = out_dir.with_name(f".{out_dir.name}.old-{staging.name.rsplit('-', 1)[-1]}")
        out_dir.rename(old)
    try:
        if old is not None and verify is not None:
            verify(old)
        staging.rename(out_dir)
    except BaseException:
        if old is not None:
            old.rename(out_dir)  # put the previous output back
        raise
    if old is not None:
        failed: list[str] = []
        if sys.version_info >= (3, 12):
            shutil.rmtree(old, onexc=lambda _f, path, err: failed.append(f"{path}: {err}"))
        else:
            shutil.rmtree(old, onerror=lambda _f, path, exc: failed.append(f"{path}: {exc[1]}"))
        if failed:
            warnings.warn(f"the previous output, set aside at {old}, could not be deleted ({failed[0]}); delete it yourself", InputWarning, stacklevel=2)
