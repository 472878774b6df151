"""Options per method: each method is a function with its own keyword-only signature, and the
verbs refuse an option the chosen method does not take, naming it and the ones it takes."""

import inspect

import numpy as np
import pytest
import scenesample as ss
from scenesample.methods import DISCRETIZE, RECONSTRUCT, options_of


def _cam(n=16):
    return ss.Camera.look_at((0, 0, 3), (0, 0, 0), (0, 1, 0), yfov=0.6, width=n, height=n)


def test_every_method_has_keyword_only_options_and_a_docstring():
    fns = [f for f, _ in DISCRETIZE.values()] + list(RECONSTRUCT.values())
    fns += [ss.methods.field_view, ss.methods.impostor_view]
    for fn in fns:
        assert fn.__doc__ and len(fn.__doc__) > 80, fn.__name__
        for p in inspect.signature(fn).parameters.values():
            if p.name not in ("scene", "cameras", "images", "field_", "imp", "camera"):
                assert p.kind is p.KEYWORD_ONLY, (fn.__name__, p.name)
    assert ss.methods.peeling is DISCRETIZE["peeling"][0]
    assert [p.name for p in options_of(ss.methods.conventional)] == ["cull_backfaces", "backend"]


@pytest.mark.parametrize(
    "method, option, value, takers",
    [
        ("conventional", "slab", None, ["visibility_field"]),
        ("peeling", "resolution", 64, ["epr", "ivir", "impostors"]),
        ("conventional", "depth", 3, []),
        ("ivir", "rho_scale", 0.5, ["epr"]),
        ("visibility_field", "octree_depth", 2, ["impostors"]),
    ],
)
def test_an_option_the_method_does_not_take_is_named(method, option, value, takers):
    scene = ss.scenes.icosphere(1)
    cams = [_cam()] if DISCRETIZE[method][1] else None
    kw = {option: value}
    if method == "peeling":
        kw["layers"] = 2
    if method == "ivir":
        kw["eye"] = _cam()
    with pytest.raises(ss.InputError) as e:
        ss.discretize(scene, cams, method, **kw)
    msg = str(e.value)
    assert f"{option}=" in msg and f"method={method!r}" in msg
    for name in options_of(DISCRETIZE[method][0]):
        assert f"{name.name}=" in msg
    for t in takers:
        assert repr(t) in msg


def test_reconstruct_checks_options_per_method(gpu):
    scene = ss.scenes.icosphere(1)
    images = ss.discretize(scene, [_cam()])
    with pytest.raises(ss.InputError, match="interpolate= does not apply to method='mesh'"):
        ss.reconstruct(images, "mesh", interpolate="uv")
    with pytest.raises(ss.InputError, match="field_view"):
        ss.reconstruct(images, "points", subsample=2)
    field = ss.discretize(scene, method="visibility_field", uv=(2, 2), st=(2, 2))
    with pytest.raises(ss.InputError, match="offset= does not apply to method='field_view'"):
        ss.reconstruct(field, _cam(), offset=images)


def test_required_options_and_cameras():
    scene = ss.scenes.icosphere(1)
    with pytest.raises(ss.InputError, match="needs layers="):
        ss.discretize(scene, [_cam()], "peeling")
    with pytest.raises(ss.InputError, match="needs eye="):
        ss.discretize(scene, method="ivir")
    with pytest.raises(ss.InputError, match="pass no cameras"):
        ss.discretize(scene, [_cam()], "visibility_field")
    with pytest.raises(ss.InputError, match="needs cameras"):
        ss.discretize(scene, method="conventional")


def test_jitter_is_a_bool_and_seed_zero_jitters():
    scene = ss.scenes.icosphere(2)
    kw = dict(method="visibility_field", uv=(4, 4), st=(4, 4), grid=(4, 4, 4))
    regular = ss.discretize(scene, **kw)
    same = ss.discretize(scene, seed=5, **kw)  # a seed without jitter changes nothing
    np.testing.assert_array_equal(regular.ids, same.ids)
    j0 = ss.discretize(scene, jitter=True, seed=0, **kw)
    j0b = ss.discretize(scene, jitter=True, seed=0, **kw)
    np.testing.assert_array_equal(j0.ids, j0b.ids)
    hits = [ss.discretize(scene, jitter=True, seed=s, ids_per_sample=4, **kw).ids for s in (0, 1)]
    assert not np.array_equal(hits[0], hits[1])
    with pytest.raises(ss.InputError, match="jitter"):
        ss.discretize(scene, jitter=1, **kw)
    with pytest.raises(ss.InputError, match="seed"):
        ss.discretize(scene, jitter=True, seed=-1, **kw)


def test_octree_depth_names_the_octree(gpu):
    ball = ss.scenes.icosphere(1)
    imp = ss.discretize(ball, method="impostors", octree_depth=1, subdivisions=0, resolution=8)
    assert imp.octree_depth == 1
    direct = ss.methods.impostors(ball, octree_depth=1, subdivisions=0, resolution=8)
    np.testing.assert_array_equal(imp.cells["index"], direct.cells["index"])
