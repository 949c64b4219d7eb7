"""fogplanes: single scattering in fog lit by rectangular lights, rendered with photon planes
weighted by continuous and stochastic multiple importance sampling (West et al. 2020), and
measured against an independent reference.

Images are numpy arrays of shape (height, width, 3), float32, linear RGB.

    >>> import fogplanes
    >>> scene = fogplanes.load_scene("media_scenes/six_lights.toml")
    >>> image = fogplanes.render(scene, "smis-exact", planes=10240, resolution=(160, 90))
    >>> ref, err = fogplanes.reference(scene, spp=256, resolution=(160, 90))
    >>> fogplanes.compare(image, ref)["mse"]  # doctest: +SKIP

Bad input raises ValueError with the command line's message, the setting named as given here
(`planes=0: ...` where the command line says `--planes: ...`), and an argument of the wrong type
TypeError, named the same way (`planes=2048.0: expected an integer, got float`); a file that
cannot be opened raises OSError (FileNotFoundError, ...). A path is what `open()` takes: a str,
bytes (decoded as `os.fsdecode` decodes them) or an os.PathLike. Ctrl-C stops a render with
KeyboardInterrupt.
"""

from ._fogplanes import (
    ACCELERATORS,
    ALLOCATOR_ENVIRONMENT,
    DEVICES,
    ESTIMATORS,
    KERNELS,
    SAMPLERS,
    Camera,
    Light,
    Medium,
    Partial,
    RenderDefaults,
    Scene,
    __version__,
    combine,
    compare,
    devices,
    finish_render,
    load_image,
    load_scene,
    merge_partials,
    merge_plan,
    plan_render,
    reference,
    reference_counts,
    reference_pilot_rows,
    reference_rows,
    render,
    render_chunk,
    save_image,
)

__all__ = [
    "ACCELERATORS",
    "ALLOCATOR_ENVIRONMENT",
    "DEVICES",
    "ESTIMATORS",
    "KERNELS",
    "SAMPLERS",
    "Camera",
    "Light",
    "Medium",
    "Partial",
    "RenderDefaults",
    "Scene",
    "__version__",
    "combine",
    "compare",
    "devices",
    "finish_render",
    "load_image",
    "load_scene",
    "merge_partials",
    "merge_plan",
    "plan_render",
    "reference",
    "reference_counts",
    "reference_pilot_rows",
    "reference_rows",
    "render",
    "render_chunk",
    "save_image",
]


def __getattr__(name: str):
    # `fogplanes.distributed` (Dask) is imported on first use: `import fogplanes` needs no Dask.
    if name == "distributed":
        import importlib

        return importlib.import_module(".distributed", __name__)
    raise AttributeError(f"module 'fogplanes' has no attribute {name!r}")
