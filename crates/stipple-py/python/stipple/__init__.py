"""stipple: render point clouds from NumPy arrays, files, scenes and out-of-core trees.

    import numpy as np, stipple
    cloud = stipple.Cloud(np.random.rand(100_000, 3))
    result = stipple.render(cloud, stipple.Camera.framing(cloud, size=(800, 600)))
    result.image   # (600, 800, 4) uint8 RGBA
    result.depth   # (600, 800) float32, +inf on background

The renderer is the one of the `stipple` command line: the same pipelines, passes, defaults
and error messages; options are its flags in snake_case (``stipple.render_options()`` lists
them). See the type stubs (``__init__.pyi``) for every class and function.
"""

from ._stipple import (
    Camera,
    Cloud,
    Renderer,
    RenderResult,
    __version__,
    build_lod,
    demo,
    read,
    render,
    render_options,
)

__all__ = [
    "Camera",
    "Cloud",
    "Renderer",
    "RenderResult",
    "__version__",
    "build_lod",
    "demo",
    "read",
    "render",
    "render_options",
]
