"""rtreflect: ray-traced reflection lines on NURBS surfaces with exact normals.

The pipeline, one sub-package per stage: exchange (scene files) → geometry (NURBS,
tessellation) → trace (camera, Embree, exact hits) → modes (tube lights) → integrator
(film) → output (image files); analysis (contours, validate) and ci (diff, goldens) on top.

The public Python API (`rtreflect.api`, documented in README.md, "Python API")::

    import rtreflect
    scene = rtreflect.load_scene("scenes/hood.toml")     # or rtreflect.Scene(surfaces=..., lights=...)
    result = rtreflect.render(scene, width=960, height=540)
    rtreflect.save(result, "out/")
    report = rtreflect.validate(scene)

Its names are imported on first use (PEP 562), so ``import rtreflect`` stays cheap.
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rtreflect")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

#: Public names, all from `rtreflect.api`, loaded when first used.
_API = ("Scene", "load_scene", "render", "save", "validate", "RenderResult", "SceneReport", "NurbsSurface", "CHANNELS",
        "RtreflectError", "SceneError", "SceneErrors")
__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        value = getattr(import_module(".api", __name__), name)
        globals()[name] = value  # later lookups skip this function
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
