"""The XML writing shared by ``scene.sdf``'s two writers, :mod:`exporters.sdf` (the world, room,
camera and objects) and :mod:`exporters.sdf_robot` (the robot's model): numbers as SDFormat text
and child elements. Both import it, so neither imports the other for it (no import circle)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np


def fmt(values) -> str:
    """Numbers as SDFormat text: space-separated, 9 significant digits."""
    return " ".join(f"{float(v):.9g}" for v in np.atleast_1d(values))


def sub(parent: ET.Element, tag: str, text=None, **attrib) -> ET.Element:
    """A child element ``<tag>`` of ``parent`` with ``attrib``; ``text`` is a string or numbers
    (written with :func:`fmt`)."""
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = text if isinstance(text, str) else fmt(text)
    return el
