"""Errors that reach the user as one actionable line, and the exit status of each kind.

Library code raises these (never ``sys.exit``); the CLI prints ``error: <message>`` and exits with
the class's ``exit_code``. The message must say what is wrong and what to do, on one line.

Exit statuses of ``scene-builder`` (also in ``--help`` and the README):

====  =====================================================================================
0     success
1     other failure (``check`` found problems; an unexpected error)
2     usage error: unknown command or flag, malformed flag value (argparse)
3     input error: a file that is missing, corrupt or implausible; an output folder refused
4     a learned model's weights are not available
5     an exporter produced output its consumer rejects
130   interrupted (Ctrl-C)
====  =====================================================================================

Doubtful input the build goes on with (which intrinsics source won, an alpha channel dropped)
is reported with ``warnings.warn(..., InputWarning)``; the CLI prints it as one ``warning: ...``
line.
"""

from __future__ import annotations

#: Exit status of a usage error (argparse's own status).
USAGE_EXIT_CODE = 2

#: What Pillow raises for a file (or bytes) it cannot read as an image: ``Image.open`` documents
#: ``UnidentifiedImageError`` (an OSError), ValueError and TypeError; its plugins turn malformed
#: headers into SyntaxError (its plugin API's "not my format") and EOFError, and decoding into
#: OSError ("image file is truncated", "decoder error"); ``convert`` raises ValueError for a
#: conversion it lacks; its TIFF decoder raises TypeError for a tag of the wrong type
#: ("'IFDRational' object cannot be interpreted as an integer", found by the fuzzer). Catch these
#: only around Pillow's own calls, never around the project's code.
PIL_READ_ERRORS: tuple[type[BaseException], ...] = (OSError, SyntaxError, ValueError, TypeError, EOFError)


class SceneBuilderError(Exception):
    """Base class: a failure the user can act on. ``str(err)`` is the one-line message."""

    exit_code = 1


class InputError(SceneBuilderError):
    """Bad input: missing or corrupt files, wrong sizes, invalid depth, an output folder refused."""

    exit_code = 3


class ModelUnavailableError(SceneBuilderError):
    """A learned model's weights are not available locally (and no download is possible)."""

    exit_code = 4


class ExportError(SceneBuilderError):
    """An exporter produced output that its consumer rejects (names the object when it can)."""

    exit_code = 5


class EmptySceneError(InputError):
    """Perception found nothing to build (no objects, no floor)."""


class InputWarning(UserWarning):
    """Doubtful input the build goes on with; the message says what was assumed."""
