"""Type stubs for stipple, the point-cloud renderer (the `stipple` command line's library)."""

from os import PathLike
from typing import Any, Mapping, Sequence

import numpy as np
import numpy.typing as npt

__version__: str

_Path = str | PathLike[str]
_Vec3 = Sequence[float] | npt.NDArray[np.floating[Any]]
_Size = int | tuple[int, int]

class Cloud:
    """A point cloud held by the renderer.

    ``positions`` is (N, 3) float32 or float64, C-contiguous. float64 positions are stored as
    float32 offsets from a float64 ``origin`` (default: the centre of their bounds), so LiDAR
    coordinates keep millimetres. Optional columns, N rows each: ``normals`` (N, 3) float
    (normalised), ``colors`` (N, 3) uint8, uint16 or float in 0..1, ``intensity`` (N,) integer
    or float in 0..65535, ``opacity`` (N,) float in 0..1, ``classification`` (N,) uint8 ASPRS
    codes. The arrays are copied once into the cloud's columns, so any memory layout is taken
    (strided views such as laspy's columns included). Bad arrays (wrong shape or dtype, NaN or
    inf, values out of range) raise ``ValueError`` naming the argument.

    A render that needs normals estimates them (and splat radii) once and keeps them in the
    cloud: ``cloud.normals`` then returns them and later renders skip the estimation.
    """

    def __init__(
        self,
        positions: npt.NDArray[np.floating[Any]],
        normals: npt.NDArray[np.floating[Any]] | None = None,
        colors: npt.NDArray[Any] | None = None,
        intensity: npt.NDArray[Any] | None = None,
        opacity: npt.NDArray[np.floating[Any]] | None = None,
        origin: tuple[float, float, float] | None = None,
        classification: npt.NDArray[np.uint8] | None = None,
    ) -> None: ...
    def __len__(self) -> int: ...
    def info(self) -> dict[str, Any]:
        """count, bounds ((xmin, ymin, zmin), (xmax, ymax, zmax)) in world units, origin,
        spacing (median nearest-neighbour distance), attributes, z_up, source."""
    @property
    def positions(self) -> npt.NDArray[np.float64]:
        """World positions (N, 3), a copy."""
    @property
    def normals(self) -> npt.NDArray[np.float32] | None:
        """Unit normals (N, 3) or None, a copy."""
    @property
    def colors(self) -> npt.NDArray[np.uint8] | None:
        """sRGB colours (N, 3) or None, a copy."""
    @property
    def intensity(self) -> npt.NDArray[np.uint16] | None: ...
    @property
    def opacity(self) -> npt.NDArray[np.float32] | None: ...
    @property
    def classification(self) -> npt.NDArray[np.uint8] | None: ...
    @property
    def radius(self) -> npt.NDArray[np.float32] | None:
        """Splat radii (N,) in world units, or None."""
    @property
    def origin(self) -> tuple[float, float, float]: ...
    def save(self, path: _Path, overwrite: bool = False) -> None:
        """Writes .ply, .las, .laz or .xyz (with estimated normals and radii). An existing
        file is kept (FileExistsError) unless overwrite=True."""

def read(path: _Path, iso: float | None = None, transfer: str | None = None) -> Cloud:
    """Reads any cloud file the command line reads: PLY (.ply, .ply.gz), LAS/LAZ/COPC,
    XYZ/TXT/CSV, PCD, E57, OBJ/STL (vertices), and volumes (.nrrd, .nii, .nii.gz, raw) as
    their iso-surface at ``iso`` (default: Otsu's threshold), or through the transfer
    function ``transfer`` (as ``--transfer``: a file of ``value r g b opacity`` lines, or the
    points inline separated by ``;``): every sample it shows becomes a point with its colour
    and opacity. A missing file raises FileNotFoundError, a malformed one (or a bad
    function) ValueError naming it."""

def demo(name: str = "plane-objects", points: int | None = None, seed: int = 1) -> Cloud:
    """A built-in demo scene: plane-objects, sphere, torus, nested-tori."""

class Camera:
    """The command line's camera: right-handed, looking from ``eye`` to ``target``; ``fov``
    is vertical, in degrees (default 45), or ``ortho`` gives an orthographic view height.
    ``size`` is (width, height) or one number for a square (default 1024). Near and far are
    fitted to the cloud rendered unless given (as ``stipple render`` does)."""

    def __init__(
        self,
        eye: _Vec3,
        target: _Vec3,
        up: _Vec3 | None = None,
        fov: float | None = None,
        size: _Size | None = None,
        near: float | None = None,
        far: float | None = None,
        ortho: float | None = None,
    ) -> None: ...
    @staticmethod
    def framing(
        cloud: Cloud, size: _Size | None = None, fov: float | None = None, view: str | None = None
    ) -> Camera:
        """The default view of ``stipple render``: the whole cloud framed (Z-up for LiDAR,
        Y-up for scanned objects), or the sensor's view where the file records it."""
    @staticmethod
    def from_json(text: str) -> Camera:
        """Reads ``stipple render --camera-out`` JSON."""
    def to_json(self) -> str:
        """The ``--camera-out`` JSON (eye, target, up, fov, size, near, far, matrices)."""
    def replace(
        self,
        eye: _Vec3 | None = None,
        target: _Vec3 | None = None,
        up: _Vec3 | None = None,
        fov: float | None = None,
        size: _Size | None = None,
    ) -> Camera:
        """A copy with the fields given changed (near and far fitted again)."""
    @property
    def eye(self) -> tuple[float, float, float]: ...
    @property
    def target(self) -> tuple[float, float, float]: ...
    @property
    def up(self) -> tuple[float, float, float]: ...
    @property
    def fov(self) -> float | None: ...
    @property
    def ortho(self) -> float | None: ...
    @property
    def size(self) -> tuple[int, int]: ...
    @property
    def near(self) -> float | None: ...
    @property
    def far(self) -> float | None: ...

class RenderResult:
    """One frame. The arrays are made from the renderer's buffers (no copy of the image)."""

    @property
    def image(self) -> npt.NDArray[np.uint8]:
        """(H, W, 4) RGBA, sRGB: the pixels of the PNG ``stipple render`` writes."""
    @property
    def depth(self) -> npt.NDArray[np.float32]:
        """(H, W) view-axis depth, +inf on background (``--depth-out``)."""
    @property
    def normals(self) -> npt.NDArray[np.float32] | None:
        """(H, W, 3) world-space unit normals facing the eye, NaN on background
        (``--normal-out``); made on first access."""
    @property
    def camera(self) -> Camera:
        """The camera used, near and far included."""
    @property
    def stats(self) -> dict[str, float]:
        """Milliseconds per pass."""
    @property
    def ms(self) -> float:
        """Milliseconds of the frame (after normal estimation and shadows)."""
    @property
    def notes(self) -> list[str]:
        """What the renderer decided and suggests (the CLI prints these)."""
    @property
    def pipeline(self) -> str:
        """dobrev, splat or raw."""
    @property
    def backend(self) -> str: ...
    def save(self, path: _Path, overwrite: bool = False) -> None:
        """Writes the image as PNG."""

class Renderer:
    """A source (a Cloud, or the path of a cloud file, a scene file or a .stlod tree) with a
    backend and options, for many cameras: the cloud stays uploaded and its normals
    estimated between renders. Rendering releases the GIL; Ctrl-C raises KeyboardInterrupt.
    """

    def __init__(
        self,
        source: Cloud | _Path,
        pipeline: str = "auto",
        backend: str = "auto",
        **options: Any,
    ) -> None: ...
    def render(self, camera: Camera | None = None) -> RenderResult: ...
    @property
    def default_camera(self) -> Camera:
        """The camera used when none is given (the CLI's: framing the cloud, scene or tree)."""
    @property
    def backend(self) -> str: ...

def render(
    source: Cloud | _Path,
    camera: Camera | None = None,
    pipeline: str = "auto",
    backend: str = "auto",
    **options: Any,
) -> RenderResult:
    """Renders once. ``pipeline``: auto, dobrev, splat or raw; ``backend``: auto, cpu or gpu.
    ``options`` are ``stipple render``'s flags in snake_case (``layers=2, opacity=0.5``,
    ``shading="edl"``, ``no_lighting=True``, ``background=(0, 0, 0)``,
    ``light="disc:0,2,1,0.2", shadows=True``); ``render_options()`` lists them. A bad option raises
    ValueError naming it."""

def render_options() -> Mapping[str, str]:
    """Every option of ``render`` and ``Renderer`` with its help text."""

def build_lod(
    inputs: _Path | Sequence[_Path],
    output: _Path,
    memory: int | str | None = None,
    **options: Any,
) -> None:
    """Builds a .stlod multi-resolution tree (``stipple build-lod``) from cloud files of any
    size; render it with ``render(output, camera, point_budget=...)``. ``memory``: bytes or
    "4G". An interrupt stops the build and leaves no tree."""
