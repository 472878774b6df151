"""What a newcomer sees first: lit frames that read on every shared scene, the demo's labelled
contact sheet and gallery, and output free of stray driver errors."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import scenesample as ss
from conftest import SHARED, load_quiet, orbit_cameras
from scenesample import _env
from scenesample.imageio import KEY, auto_exposure, labelled_sheet

#: The shading model's ambient radiance, as a fraction of the albedo (src/shading.rs).
AMBIENT = 0.08
#: Rec. 709 luminance weights.
LUMA = np.array([0.2126, 0.7152, 0.0722])


def srgb_luminance(rgb8: np.ndarray, mask: np.ndarray) -> float:
    """Mean luminance of the masked pixels of an sRGB uint8 image, 0..1 in display values."""
    return float((rgb8[mask].astype(np.float64) / 255 @ LUMA).mean())


@pytest.mark.parametrize("name", sorted(SHARED))
def test_lit_frames_of_every_shared_scene_read(name, gpu):
    """A lit frame shows its shapes: as shaded, a fair share of its surface pixels are lit
    well above the ambient floor of their own colour (the default light joins a scene's lights
    that leave the view dark; a dark material lit is still lit: the toy car's body is dark
    green where its texture's mean was a light grey), and with auto exposure the mean display
    luminance is mid-tone: neither a dark shape on black nor a white silhouette."""
    scene = load_quiet(SHARED[name])
    cam = orbit_cameras(scene, 1, 96, 96, seed=1)[0]
    frame = ss.render(scene, cam, effects=[])
    mask = frame.mask
    assert mask.sum() > 50, f"{name}: the view sees almost nothing"
    albedo = ss.discretize(scene, [cam]).color[0][mask].astype(np.float64) @ LUMA
    shaded = frame.image[mask].astype(np.float64) @ LUMA
    bright = shaded > 4 * AMBIENT * albedo
    assert bright.mean() >= 0.1, f"{name}: {bright.mean():.1%} of the surface reads as lit"
    shown = srgb_luminance(frame.to_srgb8("auto"), mask)
    assert 0.2 <= shown <= 0.75, f"{name}: mean display luminance {shown:.3f} with auto exposure"
    assert isinstance(frame.stats["default_light"], bool)


def test_a_scene_without_lights_gets_the_default_light_and_says_so():
    scene = ss.scenes.shapes(seed=0, detail=1)
    assert not scene.lights
    cam = orbit_cameras(scene, 1, 48, 48)[0]
    frame = ss.render(scene, cam, effects=[])
    assert frame.stats["default_light"] is True


def test_auto_exposure_meters_the_log_average_to_mid_grey():
    rng = np.random.default_rng(0)
    img = rng.uniform(0.01, 0.05, (16, 16, 3)).astype(np.float32)
    k = auto_exposure(img)
    lum = img.astype(np.float64) @ LUMA
    assert np.exp(np.log(lum * k + 1e-6 * k).mean()) == pytest.approx(KEY, rel=1e-3)
    assert auto_exposure(np.zeros((4, 4, 3), np.float32)) == 1.0  # nothing lit: unchanged
    assert auto_exposure(np.full((4, 4, 3), 1e-9, np.float32)) == 16.0  # clamped
    frame_like = ss.Frame(image=img, plan=[], effects={}, mask=np.ones((16, 16), bool))
    with pytest.raises(ss.InputError, match="exposure"):
        frame_like.to_srgb8(-1.0)
    with pytest.raises(ss.InputError, match="exposure"):
        frame_like.to_srgb8("bright")


def test_the_labelled_sheet_draws_its_labels():
    tile = np.full((40, 50, 3), 128, np.uint8)
    sheet = labelled_sheet([[tile, tile], [tile, tile]], ["a", "b"], ["view 0", "view 1"])
    assert sheet.dtype == np.uint8 and sheet.shape[0] > 80 and sheet.shape[1] > 100
    h, w = sheet.shape[0] - 80, sheet.shape[1] - 100  # the margins: labels, drawn in white
    assert (sheet[:h] > 200).any() and (sheet[:, :w] > 200).any()
    assert (sheet[h:, w:] == 128).all()  # the tiles themselves untouched
    with pytest.raises(ValueError, match="label"):
        labelled_sheet([[tile]], ["a", "b"], ["r"])


def test_headless_vulkan_only_where_no_display_can_be_reached(tmp_path):
    env: dict[str, str] = {}
    assert _env.headless_vulkan(env) and env == {"NODEVICE_SELECT": "1"}
    for kept in (
        {"NODEVICE_SELECT": "0"},
        {"WAYLAND_DISPLAY": "wayland-0"},
        {"DISPLAY": ":0"},
        {"XDG_RUNTIME_DIR": str(tmp_path)},
    ):
        before = dict(kept)
        assert not _env.headless_vulkan(kept) and kept == before
    missing = {"XDG_RUNTIME_DIR": str(tmp_path / "gone")}
    assert _env.headless_vulkan(missing) and missing["NODEVICE_SELECT"] == "1"


def ci_environment() -> dict[str, str]:
    """This process's environment without a display server, as CI has it."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("XDG_RUNTIME_DIR", "WAYLAND_DISPLAY", "DISPLAY", "NODEVICE_SELECT")
    }
    return env


@pytest.mark.slow
def test_the_quick_demo_writes_its_images_and_prints_no_error_line(tmp_path, gpu):
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "scenesample.demo", "--quick", "--out", str(out)],
        env=ci_environment(),
        capture_output=True,
        text=True,
        timeout=900,
    )
    text = r.stdout + r.stderr
    assert r.returncode == 0, text[-3000:]
    errors = [line for line in text.splitlines() if "error:" in line.lower()]
    assert not errors, errors
    for name in ("contact_sheet.png", "gallery.png", "views.exr", "view0_lit.png"):
        assert (out / name).stat().st_size > 1000, name
    assert "| gallery: one panel per paper |" in r.stdout
    # The quick gallery (gallery.make(out, gallery.QUICK)): four panels and a sweep.
    from PIL import Image

    img = np.asarray(Image.open(out / "gallery.png").convert("RGB"))
    assert img.shape[0] > 400 and img.shape[1] > 800
    assert img.std() > 10  # panels, not a blank page


#: Run before the demo in a subprocess: these top-level packages cannot be imported, as on a
#: machine where only the wheel (and numpy) is installed.
HIDE_PACKAGES = """
import importlib.abc, sys
class Hidden(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in HIDDEN:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, Hidden())
"""


@pytest.mark.parametrize(
    "hidden, named",
    [(("matplotlib",), ("the gallery (matplotlib)",)), (("matplotlib", "PIL"), ("(pillow)",))],
)
def test_the_demo_without_its_extras_does_the_rest_and_names_them_in_one_line(
    tmp_path, gpu, hidden, named
):
    out = tmp_path / "out"
    code = (
        f"HIDDEN = {hidden!r}\n{HIDE_PACKAGES}\nimport runpy\n"
        f"sys.argv = ['demo', '--quick', '--procedural', '--out', {str(out)!r}]\n"
        "runpy.run_module('scenesample.demo', run_name='__main__')\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code],
        env=ci_environment(),
        capture_output=True,
        text=True,
        timeout=600,
    )
    text = r.stdout + r.stderr
    assert r.returncode == 0 and "Traceback" not in text, text[-3000:]
    advice = [line for line in text.splitlines() if "pip install" in line]
    assert len(advice) == 1, advice
    assert advice[0].endswith("pip install 'scenesample[demo]'"), advice
    assert all(n in advice[0] for n in named), advice
    assert "| gallery: one panel per paper | skipped |" in r.stdout
    for name in ("contact_sheet.png", "views.exr", "view0_lit.png"):
        assert (out / name).stat().st_size > 1000, name
    assert not (out / "gallery.png").exists()


def test_a_missing_optional_package_is_a_typed_import_error_that_pickles():
    import pickle

    from scenesample import _optional

    with pytest.raises(ss.MissingDependencyError) as caught:
        _optional.require("matplotlib.no_such_module", "a test")
    e = caught.value
    assert isinstance(e, ImportError) and isinstance(e, ss.ScenesampleError)
    assert str(e) == "a test needs matplotlib: pip install 'scenesample[demo]'"
    again = pickle.loads(pickle.dumps(e))
    assert (again.purpose, again.package, again.extra, str(again)) == (
        "a test",
        "matplotlib",
        "demo",
        str(e),
    )
