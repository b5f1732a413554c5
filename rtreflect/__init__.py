"""rtreflect: ray-traced reflection lines on NURBS surfaces with exact normals.

The pipeline (DESIGN.md): scene → surfaces → tessellation → accelerator → camera
rays → exact hits (tracing) → lights and modes → film → image files.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rtreflect")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"
