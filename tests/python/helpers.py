"""What the Python tests share: the repository's paths and exact image comparison."""

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SIX_LIGHTS = ROOT / "media_scenes" / "six_lights.toml"


def bits(a: np.ndarray) -> np.ndarray:
    """The float32 bit patterns, so that equality is exact (-0.0 differs from 0.0, NaN == NaN)."""
    assert a.dtype == np.float32
    return np.ascontiguousarray(a).view(np.uint32)


def assert_bit_identical(a: np.ndarray, b: np.ndarray) -> None:
    assert a.shape == b.shape and a.dtype == b.dtype == np.float32
    assert np.array_equal(bits(a), bits(b)), f"{np.count_nonzero(bits(a) != bits(b))} values differ"
