"""One evaluate for images: any image-like result against any image-like reference of the same
size gets the same keys, computed on the 8-bit sRGB display of both."""

import numpy as np
import pytest
import scenesample as ss

KEYS = {"rmse", "psnr", "max_abs", "pixel_error", "coverage_difference"}


@pytest.fixture(scope="module")
def results(gpu):
    scene = ss.scenes.icosphere(2)
    cam = ss.Camera.look_at((2.5, 1.0, 1.5), (0, 0, 0), (0, 0, 1), yfov=0.8, width=48, height=48)
    imp = ss.discretize(scene, method="impostors", octree_depth=1, subdivisions=1, resolution=32)
    light = ss.AreaLight((0, 0, 3), (0.3, 0, 0), (0, 0.3, 0))
    return {
        "DepthImages": ss.discretize(scene, cam),
        "ImpostorView": ss.reconstruct(imp, cam),
        "triangles": ss.ImpostorView.of_triangles(scene, cam),
        "Frame": ss.render(scene, cam),
        "ShadowResult": ss.soft_shadows(
            scene, cam, light, samples=(2, 2), discretization="raytraced"
        ),
        "array": np.full((48, 48, 3), 0.25, np.float32),
    }


def test_every_pair_of_images_gets_the_same_keys(results):
    for a_name, a in results.items():
        for b_name, b in results.items():
            m = ss.evaluate(a, b, "image")
            assert set(m) == KEYS, (a_name, b_name)
            assert 0 <= m["coverage_difference"] <= 1 and m["max_abs"] <= 255
            if a is b:
                assert m["rmse"] == 0 and m["pixel_error"] == 0 and m["psnr"] == np.inf


def test_impostors_against_depth_images_by_default(results):
    m = ss.evaluate(results["ImpostorView"], results["DepthImages"])
    assert set(m) == KEYS
    # Both see the sphere; the impostor view differs at the outline only (32^2 impostors).
    assert 0 < m["coverage_difference"] < 0.15
    same = ss.evaluate(results["triangles"], results["DepthImages"])
    assert same["coverage_difference"] < 0.005
    paper = ss.evaluate(results["ImpostorView"], results["triangles"])
    assert "error_per_foreground_pixel" in paper and "gap_pixels" in paper


def test_the_metric_follows_the_display_and_the_coverage():
    black = np.zeros((4, 4, 3))
    white = np.ones((4, 4, 3))
    m = ss.evaluate(white, black, "image")
    assert m["rmse"] == 255 and m["pixel_error"] == 4 * 4 * 3 * 255 and m["psnr"] == 0
    mid = ss.evaluate(np.full((4, 4), 0.214), black, "image")  # linear 0.214 ~ sRGB 128
    assert abs(mid["max_abs"] - 128) <= 1


def test_mismatched_sizes_and_non_images_are_refused(results):
    with pytest.raises(ss.InputError, match="ImpostorView"):
        ss.evaluate(results["ImpostorView"], np.zeros((4, 4, 3)), "image")
    with pytest.raises(ss.InputError, match="image-like"):
        ss.evaluate(results["Frame"], ss.scenes.icosphere(1), "image")
    with pytest.raises(ss.InputError, match="ImpostorViews"):
        ss.evaluate(results["DepthImages"], results["triangles"], "impostor")
