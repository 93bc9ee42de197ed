"""Errors that reach the user as one actionable line.

Library code raises these (never ``sys.exit``); the CLI prints ``error: <message>`` and exits
non-zero. The message must say what is wrong and what to do, on one line.
"""

from __future__ import annotations


class SceneBuilderError(Exception):
    """Base class: a failure the user can act on. ``str(err)`` is the one-line message."""

    exit_code = 1


class InputError(SceneBuilderError):
    """Bad input: missing or corrupt files, wrong sizes, invalid depth, bad flags."""

    exit_code = 2


class ModelUnavailableError(SceneBuilderError):
    """A learned model's weights are not available locally (and no download is possible)."""

    exit_code = 3


class ExportError(SceneBuilderError):
    """An exporter produced output that its consumer rejects (names the object when it can)."""

    exit_code = 4


class EmptySceneError(InputError):
    """Perception found nothing to build (no objects, no floor)."""
