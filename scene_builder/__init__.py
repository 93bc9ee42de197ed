"""scene-builder: one photo of a room in, a simulation-ready digital twin out.

Importing this package is cheap: heavy libraries are imported inside the functions that use them.
"""

__version__ = "0.1.0"
