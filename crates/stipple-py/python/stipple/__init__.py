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

import os as _os

# Mesa's device-select Vulkan layer asks a Wayland compositor which GPU drives the display;
# with no desktop session (ssh, containers, a notebook server: XDG_RUNTIME_DIR unset)
# libwayland prints "error: XDG_RUNTIME_DIR is invalid or not set" twice on the first GPU
# render, though nothing failed. stipple ranks adapters itself, so the layer adds nothing
# there: switch it off with its own switch, as the command line does, unless the user set
# it or asked the layer for a device.
if not _os.environ.get("XDG_RUNTIME_DIR") and not any(
    _os.environ.get(v) for v in ("NODEVICE_SELECT", "MESA_VK_DEVICE_SELECT")
):
    _os.environ["NODEVICE_SELECT"] = "1"

from ._stipple import (  # noqa: E402
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
