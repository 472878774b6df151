"""Colour and shading normals as the viewers users compare with draw them, on shared scenes
(issue 72, item 5): our ``color`` against pyrender's unlit render of the same file and camera,
and ``shading_normal`` against the file's own normals read by trimesh and interpolated in
numpy (``python -m scenesample.experiments viewers`` writes the full table)."""

from __future__ import annotations

import warnings

import pytest
import scenesample as ss
from conftest import SHARED
from scenesample.tools.experiments.viewers import compare


@pytest.mark.parametrize("name", ["balloon", "khr_clearcoat_car_paint"])
def test_colour_and_normals_agree_with_pyrender_and_the_file(name, gpu):
    """balloon: textured (19 materials); the clear-coat car paint: one smooth-shaded sphere.
    The issue's targets: colour median <= 2/255 and 95th percentile <= 16/255 where texels
    are magnified (pyrender's mip chain averages sRGB-encoded texels, ours linear ones, so
    minified pixels may differ more); normals median <= 0.5 deg and 99th percentile <= 3
    deg."""
    pytest.importorskip("pyrender")
    if name not in SHARED:
        pytest.skip(f"{name} is not among the shared scenes")
    # The backends share the resolve: both on the textured scene, the CPU's on the other.
    for backend in ("gpu", "cpu") if name == "balloon" else ("cpu",):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ss.SceneWarning)
            row, _ = compare(name, 512, backend)
        assert row["pixels"] > 50_000 and row["normal_pixels"] > 0.99 * row["pixels"], row
        assert row["magnified_pixels"] > 0.5 * row["pixels"], row
        assert row["magnified_median"] <= 2 and row["magnified_p95"] <= 16, row
        assert row["normal_median_deg"] <= 0.5 and row["normal_p99_deg"] <= 3, row
        # The geometric normal is what the images carried as their only normal before.
        assert row["geometric_median_deg"] > 1, row
