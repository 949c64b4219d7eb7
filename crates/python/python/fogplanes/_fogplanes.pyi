"""Type stubs of the native module fogplanes._fogplanes (crates/python/src/lib.rs)."""

import os
from collections.abc import Iterable, Mapping
from typing import Final, Literal, TypeAlias, TypedDict, overload

import numpy as np
import numpy.typing as npt

__version__: Final[str]
#: Every estimator name, in the order of the paper (`fogplanes.weights::Estimator::names()`).
ESTIMATORS: Final[tuple[str, ...]]
#: The gathering kernels: auto, avx512, avx2, portable, per-hit (all give identical images).
KERNELS: Final[tuple[str, ...]]
SAMPLERS: Final[tuple[str, ...]]
#: How rays find planes: raster, bvh, brute-force.
ACCELERATORS: Final[tuple[str, ...]]
#: The processors that gather: cpu, gpu (through wgpu: Vulkan, Metal, DX12), auto (a GPU when
#: one is found, not an emulated adapter such as lavapipe, else the CPU). docs/gpu.md says what
#: is identical where.
DEVICES: Final[tuple[str, ...]]
#: glibc's allocator settings a render's process runs best with, as the environment variables
#: glibc reads when a process starts (MALLOC_MMAP_THRESHOLD_, MALLOC_TRIM_THRESHOLD_: bytes, as
#: text): the command line sets them for itself, and fogplanes.distributed's local cluster for its
#: workers; a cluster of your own can export them for its workers (docs/cluster.md).
ALLOCATOR_ENVIRONMENT: Final[Mapping[str, str]]

Vec3: TypeAlias = tuple[float, float, float]
Image: TypeAlias = npt.NDArray[np.float32]
"""An image: shape (height, width, 3), float32, linear RGB."""
PathLike: TypeAlias = str | bytes | os.PathLike[str] | os.PathLike[bytes]
"""A path as `open()` takes it: bytes are decoded as `os.fsdecode` decodes them (on POSIX the
file system's own bytes, unchanged). Anything else is a TypeError naming the argument."""

class Camera:
    """The pinhole camera of a scene."""

    @property
    def position(self) -> Vec3: ...
    @property
    def forward(self) -> Vec3:
        """Unit view direction."""
    @property
    def right(self) -> Vec3:
        """Unit right vector of the image plane."""
    @property
    def up(self) -> Vec3:
        """Unit up vector of the image plane (orthogonal to forward)."""
    @property
    def vfov_deg(self) -> float:
        """Vertical field of view in degrees."""
    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) in pixels."""

class Medium:
    """The homogeneous fog: an axis-aligned box, vacuum outside."""

    @property
    def min(self) -> Vec3: ...
    @property
    def max(self) -> Vec3: ...
    @property
    def sigma_s(self) -> Vec3:
        """Scattering coefficient, RGB, per unit length."""
    @property
    def sigma_a(self) -> Vec3:
        """Absorption coefficient, RGB, per unit length."""
    @property
    def sigma_t(self) -> Vec3:
        """Extinction sigma_s + sigma_a."""
    @property
    def g(self) -> float:
        """Henyey-Greenstein asymmetry in [-0.99, 0.99]: 0 isotropic, positive scatters forward."""

class Light:
    """A one-sided rectangular light: corner + p edge_u/|edge_u| + q edge_v/|edge_v|."""

    @property
    def name(self) -> str:
        """The light's name (light<i> when the file gives none)."""
    @property
    def corner(self) -> Vec3: ...
    @property
    def edge_u(self) -> Vec3:
        """First edge (|edge_u| times its unit direction, as stored after validation)."""
    @property
    def edge_v(self) -> Vec3:
        """Second edge, orthogonal to the first."""
    @property
    def normal(self) -> Vec3:
        """Unit normal normalize(edge_u x edge_v): the side the light emits to."""
    @property
    def radiance(self) -> Vec3: ...
    @property
    def area(self) -> float: ...

class RenderDefaults:
    """The scene file's [render] table, defaults filled in."""

    @property
    def planes(self) -> int: ...
    @property
    def estimator(self) -> str: ...
    @property
    def orientations(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def spp(self) -> int: ...
    @property
    def sampler(self) -> str: ...
    @property
    def lobes(self) -> float: ...

class Scene:
    """A validated scene: camera, fog box, rectangular lights and render defaults. Read-only.

    Made by `load_scene(path)` or `Scene.from_toml(text)`.
    """

    @staticmethod
    def from_toml(text: str, name: str = "scene", file: str = "<string>") -> Scene:
        """Parses and validates scene text (TOML, the schema of media_scenes/*.toml).

        `name` is the scene's name; `file` names the text in error messages. Raises ValueError
        with the file, line, field and problem for anything invalid, TypeError naming the
        argument for one that is not a str (bytes too: decode the text first).
        """
    def with_resolution(self, width: int, height: int) -> Scene:
        """The same scene at another resolution."""
    @staticmethod
    def _from_parts(text: str, name: str, file: str, resolution: tuple[int, int]) -> Scene:
        """The scene rebuilt from its text, name, file and resolution (unpickling)."""
    def __reduce__(self) -> tuple[object, tuple[str, str, str, tuple[int, int]]]: ...
    def __dask_tokenize__(self) -> str:
        """A stable token: 32 hex digits hashing text, name, file and resolution."""
    @property
    def source(self) -> str:
        """The TOML text the scene was made from."""
    @property
    def file(self) -> str:
        """The file name its errors cite."""
    @property
    def name(self) -> str:
        """The file stem (or the name given to from_toml)."""
    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) in pixels."""
    @property
    def camera(self) -> Camera: ...
    @property
    def medium(self) -> Medium: ...
    @property
    def lights(self) -> list[Light]:
        """The lights, in file order."""
    @property
    def render(self) -> RenderDefaults:
        """The [render] defaults: planes, estimator, orientations, seed, spp."""

class RenderStats(TypedDict):
    """What a render measured (wall-clock seconds), as `fogplanes render` prints it."""

    estimator: str
    kernel: str
    #: The device that gathered: "cpu", or "gpu: " and the adapter's name (of `finish_render`
    #: and `fogplanes.distributed.render`: the partials' `devices`, joined by "; ").
    device: str
    #: The devices whose gathering the image holds, each once (a `finish_render` of partials
    #: gathered on several devices names them all).
    devices: list[str]
    #: Seconds of the GPU's own gather (its timestamps, else the wall time of its work); 0 on the CPU.
    seconds_device: float
    #: Of seconds_device, the gather's and its reduction's (the rest: the planes' reach and
    #: their binning), where the GPU has timestamps; else 0.
    seconds_device_gather: float
    #: Seconds of wall time uploading to the GPU (the planes, each ray set's rays: their
    #: writing, straight into the upload buffers, is in seconds_rays); 0 on the CPU.
    seconds_upload: float
    #: Seconds of wall time waiting for the GPU's work to end (each chunk's sums read back);
    #: 0 on the CPU.
    seconds_waited: float
    #: Bytes that crossed between the CPU and the GPU (planes up, sums back); 0 on the CPU.
    bytes_crossed: int
    #: The GPU's queue submissions; 0 on the CPU.
    submissions: int
    #: The GPU's gather dispatches (a round of batches of planes each); 0 on the CPU.
    gather_dispatches: int
    planes: int
    #: 1, or the passes of a render on a time budget.
    plane_passes: int
    rays: int
    hits: int
    tests: int
    seconds_sampling: float
    seconds_build: float
    seconds_rays: float
    seconds_gather: float
    seconds_total: float
    hits_per_ray: float
    gather_ns_per_hit: float
    #: The estimated relative RMS error of the image, with an error image (else None; None too
    #: for a black image, whose relative error is 0/0: "relative_error_text" says which).
    relative_error: float | None
    #: The part of "relative_error" that planes do not lower, the direct emission's error
    #: (docs/mathematics.md section 10.3): a `target_error` below it is out of reach.
    error_floor: float | None
    #: The relative error as the summary words it, e.g. "undefined (the image is black)"; None
    #: without an error image. Never "inf" or "nan".
    relative_error_text: str | None
    #: Why a render in passes stopped: "time budget", "target error", "plane limit", "error
    #: floor" (the target lies below "error_floor") or "black image" (else None).
    stopped_by: str | None
    summary: str

Metrics = TypedDict(
    "Metrics",
    {"smape": float, "mse": float, "rel_mse": float, "relmse": float, "max_abs": float},
)

def load_scene(path: PathLike) -> Scene:
    """Reads and validates a scene file (TOML).

    Raises FileNotFoundError (an OSError) if the file cannot be opened, ValueError naming the
    file, line and field if its content is invalid, TypeError naming `path` for anything but a
    path.
    """

@overload
def render(
    scene: Scene | PathLike,
    estimator: str | None = None,
    *,
    planes: int | None = None,
    seed: int | None = None,
    spp: int | None = None,
    pixel_center: bool = False,
    resolution: tuple[int, int] | None = None,
    orientations: int | None = None,
    threads: int | None = None,
    accelerator: str = "raster",
    kernel: str = "auto",
    device: str = "cpu",
    return_stats: Literal[False] = False,
    sampler: str | None = None,
    lobes: float | None = None,
    time_budget: float | None = None,
    target_error: float | None = None,
    return_stderr: Literal[False] = False,
    progress: bool = False,
) -> Image:
    """Renders a scene with photon planes: the image, shape (height, width, 3), float32.

    The arguments are those of `fogplanes render`, and None takes the scene's [render]
    default exactly as the command line does (both resolve them in the core): `estimator`
    (the scene's, else smis-exact), `planes`, `seed`, `spp`, and `orientations` (the scene's K
    applies only when the scene's estimator is the one rendered). `resolution` is (width,
    height). Pixels are whole: the mean over each pixel's square (box filter), with `spp` camera
    samples per pixel (the scene's, else 16) sharing the planes; `pixel_center=True` takes the
    centres. `time_budget` renders for that many seconds instead of a plane count: planes in
    passes, each extending the set (the stats give "planes" and "plane_passes");
    `target_error` renders passes until the estimated relative RMS error of the image falls
    below it (with `time_budget`, whichever comes first; the stats' "stopped_by" says which),
    or stops as soon as it is shown out of reach: below the stats' "error_floor", the direct
    emission's error that planes do not lower, or for a black image.
    `threads` runs the render in a pool of that many threads (None: all cores); the image
    depends on the seed alone. The image is bit-identical to the EXR that `fogplanes render`
    writes for the same arguments. `sampler` is where the planes' random numbers come from:
    "sobol" (randomised quasi-Monte Carlo) or "independent" (None: the scene's, else sobol).
    `lobes` is, in fog that scatters forward or back (g != 0), the share of each light's planes
    swept along the phase function's lobe toward the eye, 0 to 1: 0 sweeps every plane by the
    cosine as the paper does (docs/mathematics.md section 2.5; None: the scene's, else 0.5).
    With `return_stderr=True`, also the estimated standard error of each pixel (as `render
    --stderr-image`); with `return_stats=True`, also the stats: (image[, stderr][, stats]).
    `device="gpu"` gathers on the GPU through wgpu (a Vulkan, Metal or DX12 adapter; ValueError
    without one), `"gpu:N"` on adapter N of `devices()`, `"auto"` on a GPU when one is found
    (not an emulated adapter such as lavapipe, which `devices()` lists too; else the CPU);
    the image agrees with the CPU's within f32 rounding (docs/gpu.md), and the stats' "device"
    says which gathered.
    `progress=True` shows progress on standard error (one line redrawn on a terminal, else a
    line per tenth of the work).

    Raises ValueError for bad input (the command line's message, the setting named as given
    here: `planes=0: ...`), OSError for a scene file that cannot be opened, KeyboardInterrupt
    on Ctrl-C. The GIL is released while rendering.
    """

@overload
def render(
    scene: Scene | PathLike,
    estimator: str | None = None,
    *,
    planes: int | None = None,
    seed: int | None = None,
    spp: int | None = None,
    pixel_center: bool = False,
    resolution: tuple[int, int] | None = None,
    orientations: int | None = None,
    threads: int | None = None,
    accelerator: str = "raster",
    kernel: str = "auto",
    device: str = "cpu",
    return_stats: Literal[True],
    sampler: str | None = None,
    lobes: float | None = None,
    time_budget: float | None = None,
    target_error: float | None = None,
    return_stderr: Literal[False] = False,
    progress: bool = False,
) -> tuple[Image, RenderStats]: ...

@overload
def render(
    scene: Scene | PathLike,
    estimator: str | None = None,
    *,
    planes: int | None = None,
    seed: int | None = None,
    spp: int | None = None,
    pixel_center: bool = False,
    resolution: tuple[int, int] | None = None,
    orientations: int | None = None,
    threads: int | None = None,
    accelerator: str = "raster",
    kernel: str = "auto",
    device: str = "cpu",
    return_stats: Literal[False] = False,
    sampler: str | None = None,
    lobes: float | None = None,
    time_budget: float | None = None,
    target_error: float | None = None,
    return_stderr: Literal[True],
    progress: bool = False,
) -> tuple[Image, Image]: ...

@overload
def render(
    scene: Scene | PathLike,
    estimator: str | None = None,
    *,
    planes: int | None = None,
    seed: int | None = None,
    spp: int | None = None,
    pixel_center: bool = False,
    resolution: tuple[int, int] | None = None,
    orientations: int | None = None,
    threads: int | None = None,
    accelerator: str = "raster",
    kernel: str = "auto",
    device: str = "cpu",
    return_stats: Literal[True],
    sampler: str | None = None,
    lobes: float | None = None,
    time_budget: float | None = None,
    target_error: float | None = None,
    return_stderr: Literal[True],
    progress: bool = False,
) -> tuple[Image, Image, RenderStats]: ...

def reference(
    scene: Scene | PathLike,
    spp: int = 1024,
    *,
    pixel_center: bool = False,
    resolution: tuple[int, int] | None = None,
    seed: int = 1,
    uniform: bool = False,
    threads: int | None = None,
) -> tuple[Image, Image]:
    """Renders the independent reference: (image, per-pixel standard error), both float32.

    As `fogplanes reference` with its -o and --stderr-image files: `spp` samples per pixel on
    average, spread by need unless `uniform`; whole pixels (box filter, as `render`), or
    `pixel_center` to compare with `render(..., pixel_center=True)`.
    """

def compare(image: npt.ArrayLike, reference: npt.ArrayLike) -> Metrics:
    """Error metrics of an image against a reference, as `fogplanes compare` prints them.

    Both are arrays of shape (height, width, 3) of any real dtype, converted to float32 (as
    the EXR files hold them). Returns smape, mse, rel_mse (also under "relmse") and max_abs.
    """

def load_image(path: PathLike) -> Image:
    """Reads the first RGB(A) layer of an EXR file: shape (height, width, 3), float32."""

def save_image(path: PathLike, image: npt.ArrayLike, exposure: float | None = None) -> None:
    """Writes an image (height, width, 3) as .exr (linear float32) or .png (sRGB, tone-mapped
    by `exposure` stops), whole or not at all. The shape is checked before any conversion; an
    `exposure` with an .exr path is a ValueError (an EXR holds linear radiance)."""

# Renders in chunks and references in row bands (the cluster layer: fogplanes.distributed).
# `**render_kwargs` are the keyword arguments of `render` but time_budget and target_error (a
# ValueError unless None: a render in chunks has a plane count) and return_stats, return_stderr
# and progress (a TypeError; finish_render takes its own return_stats).

class RenderPlan(TypedDict):
    planes: int
    #: A fixed power of two (16384): never depends on the workers or on `planes`.
    chunk_planes: int
    #: (start, end) plane ranges covering 0..planes in order.
    chunks: list[tuple[int, int]]
    #: The scene and every setting that changes the image (not threads, not kernel).
    fingerprint: str
    shape: tuple[int, int, int]
    estimator: str
    orientations: int
    seed: int
    sampler: str
    #: The share of each light's planes swept along its lobe (no matter where g = 0).
    lobes: float
    spp: int
    pixel_center: bool
    accelerator: str
    kernel: str
    #: "cpu" or "gpu:N" (`device="auto"` and "gpu" resolved where the plan is made).
    device: str
    resolution: tuple[int, int]
    threads: int | None

class AdapterInfo(TypedDict):
    """A GPU adapter as `fogplanes devices` lists it."""

    #: `device=f"gpu:{index}"` gathers on it.
    index: int
    name: str
    #: "Vulkan", "Metal" or "Dx12".
    backend: str
    #: "discrete GPU", "integrated GPU", "virtual GPU", "CPU emulation" or "other".
    kind: str
    #: The most bytes one storage buffer binding holds.
    max_binding: int
    #: Whether `device="gpu"` takes it.
    default: bool

def devices() -> list[AdapterInfo]:
    """The GPU adapters wgpu finds (Vulkan, Metal, DX12), as `fogplanes devices` lists them;
    empty where there is none."""

class Partial:
    """The unnormalised float64 sums of planes start..end of a render. Picklable; `a + b`
    adds adjacent partials of one render (ValueError otherwise)."""

    @property
    def sums(self) -> npt.NDArray[np.float64]:
        """(height, width, 3), float64 (a copy)."""
    @property
    def start(self) -> int: ...
    @property
    def end(self) -> int: ...
    @property
    def planes_total(self) -> int: ...
    @property
    def fingerprint(self) -> str: ...
    @property
    def hits(self) -> int: ...
    @property
    def seconds(self) -> float: ...
    @property
    def devices(self) -> list[str]:
        """The devices whose gathering it holds ("cpu", or "gpu: " and the adapter), each once."""
    @property
    def shape(self) -> tuple[int, int, int]: ...
    def __add__(self, other: Partial) -> Partial: ...

def plan_render(scene: Scene | PathLike, **render_kwargs: object) -> RenderPlan:
    """The resolved settings of a render in chunks, its chunks and fingerprint."""

def render_chunk(scene: Scene | PathLike, chunk: tuple[int, int], **render_kwargs: object) -> Partial:
    """Renders a plan's chunk (or a union of consecutive ones). GIL released; Ctrl-C cancels.

    `chunk` is a (start, end) tuple of plane indices: TypeError for anything else, ValueError
    naming it for a negative index (or one of 2**64 or more) and for a range that is not a union
    of the plan's chunks."""

MergeStep: TypeAlias = tuple[int, int, int | None, int | None]
"""A step of `merge_plan`: (start, end, left, right) over chunks start..end. `left` and `right`
are None for a task that renders those chunks, else the indices of the two earlier steps whose
partials it adds, left then right."""

def merge_plan(chunks: int, block: int) -> list[MergeStep]:
    """The core's plan of a render of `chunks` canonical chunks (`len(plan_render(...)["chunks"])`)
    spread over tasks that render at most `block` chunks each (a power of two): the canonical
    tree's nodes in post-order, each after the two it adds, the last the whole render. Every
    step is a node of the tree `render` adds along, so following the plan (`render_chunk` of a
    leaf's planes, `combine` of two steps) gives the bits of `render`. ValueError for no chunks,
    more than a render has (8192) or a block that is not a power of two; TypeError for
    anything but integers."""

def combine(a: Partial, b: Partial) -> Partial:
    """a + b for adjacent partials of one render (a.end == b.start)."""

def merge_partials(parts: Iterable[Partial]) -> Partial:
    """Partials in any order (a list, a tuple, any iterable) merged in the canonical order: with
    the plan's chunks, the bits of `render`. ValueError naming `parts` for different renders,
    overlaps and gaps; TypeError naming `parts` (or `parts[i]`) for anything but Partials."""

@overload
def finish_render(
    scene: Scene | PathLike, partial: Partial, return_stats: Literal[False] = False, **render_kwargs: object
) -> Image: ...
@overload
def finish_render(
    scene: Scene | PathLike, partial: Partial, return_stats: Literal[True], **render_kwargs: object
) -> tuple[Image, RenderStats]: ...
def finish_render(
    scene: Scene | PathLike, partial: Partial, return_stats: bool = False, **render_kwargs: object
) -> Image | tuple[Image, RenderStats]:
    """The image from the partial of all planes: divided by N, plus the direct emission."""

def reference_rows(
    scene: Scene | PathLike,
    rows: tuple[int, int],
    spp: int | None = None,
    counts: npt.ArrayLike | None = None,
    *,
    seed: int | None = None,
    pixel_center: bool = False,
    uniform: bool = False,
    resolution: tuple[int, int] | None = None,
    threads: int | None = None,
) -> tuple[Image, Image]:
    """Rows j0..j1 of `reference(...)`: (mean, stderr), bit-identical. The adaptive reference
    (uniform=False) needs `counts` from `reference_counts`."""

def reference_pilot_rows(
    scene: Scene | PathLike,
    rows: tuple[int, int],
    spp: int | None = None,
    *,
    seed: int | None = None,
    pixel_center: bool = False,
    resolution: tuple[int, int] | None = None,
    threads: int | None = None,
) -> Image:
    """Rows j0..j1 of the adaptive reference's pilot pass (per-pixel standard errors)."""

def reference_counts(
    scene: Scene | PathLike,
    pilot: npt.ArrayLike,
    spp: int | None = None,
    *,
    seed: int | None = None,
    pixel_center: bool = False,
    resolution: tuple[int, int] | None = None,
) -> npt.NDArray[np.uint32]:
    """Per-pixel sample counts (height, width) from the whole pilot (height, width, 3)."""
