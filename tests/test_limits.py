"""No number a user passes can abort the process: every size computed from one (rays x
max_hits, views x pixels, layers, samples, resolutions, a sweep's grid) is checked against the
memory limit before anything is allocated. Each oversized request runs in a subprocess that must
raise InputError naming the size and the limit, then go on working, and exit 0: an allocation
that aborts (Rust's response to a failed allocation) shows as a signal in the exit code."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

SETUP = textwrap.dedent(
    """
    import sys
    import numpy as np
    import scenesample as ss

    ball = ss.scenes.icosphere(2)
    room = ss.scenes.reflective_room(spheres=2)
    eye = ss.scenes.reflective_room_eye(64)
    cam = ss.Camera.look_at((3, 2, 1), (0, 0, 0), (0, 0, 1), yfov=0.8, width=64, height=48)
    huge = ss.Camera.look_at((3, 2, 1), (0, 0, 0), (0, 0, 1), yfov=0.8, width=200_000,
                             height=200_000)
    rng = np.random.default_rng(0)
    """
)

AFTER = textwrap.dedent(
    """
    try:
        call()
    except ss.InputError as e:
        message = str(e)
    else:
        sys.exit("no InputError")
    assert "memory limit" in message and "SCENESAMPLE_MEMORY_LIMIT" in message, message
    # Still working: the same scene, a small call.
    hits = ss.cast_rays(ball, np.zeros((2, 3), np.float32), np.eye(2, 3, dtype=np.float32))
    assert (hits.triangle >= 0).all()
    print(message)
    """
)

CASES = {
    "rays x max_hits": """
        o = rng.uniform(-2, 2, (1_000_000, 3)).astype(np.float32)
        d = rng.normal(size=(1_000_000, 3)).astype(np.float32)
        call = lambda: ss.cast_rays(ball, o, d, max_hits=100_000)""",
    "pixels, cpu": "call = lambda: ss.discretize(ball, huge, backend='cpu')",
    "pixels, gpu": "call = lambda: ss.discretize(ball, huge, backend='gpu')",
    "pixels, auto": "call = lambda: ss.discretize(ball, [huge, huge])",
    "pixel rays": "call = lambda: huge.pixel_rays()",
    "layers x pixels": "call = lambda: ss.discretize(ball, cam, 'peeling', layers=10**9)",
    "nonredundant": "call = lambda: ss.discretize(ball, [huge, huge], 'nonredundant')",
    "views x splat resolution": """
        pts = ss.discretize(room, method="epr", eye=eye, resolution=16)
        call = lambda: ss.splat(pts, resolution=10**6)""",
    "cube maps": "call = lambda: ss.discretize(room, method='epr', eye=eye, resolution=10**6)",
    "reflections": "call = lambda: ss.reflections(room, eye, method='mvr', resolution=10**6)",
    "omni shadows": (
        "call = lambda: ss.omni_shadows(room, eye, (0, 0.2, 1.0), 0.15, light_samples=4,"
        " resolution=10**6)"
    ),
    "soft shadows": """
        light = ss.AreaLight.above(ball, size=1.0)
        call = lambda: ss.soft_shadows(ball, cam, light, samples=(10**6, 10**6))""",
    "field": (
        "call = lambda: ss.discretize(ball, method='visibility_field', uv=(10**4, 10**4),"
        " st=(10**4, 10**4))"
    ),
    "impostors": (
        "call = lambda: ss.discretize(ball, method='impostors', octree_depth=4, subdivisions=5,"
        " resolution=4096)"
    ),
    "omni light samples": (
        "call = lambda: ss.omni_shadows(room, eye, (0, 0.2, 1.0), 0.15, light_samples=10**9)"
    ),
    "reflection reference": "call = lambda: ss.reflection_reference(room, eye, factor=10**5)",
    "render": "call = lambda: ss.render(room, huge)",
    "intermediate views": """
        nr = ss.discretize(ball, [cam, cam], "nonredundant")
        call = lambda: ss.evaluate(nr, ball, intermediate=10**9)""",
    "field view": """
        field = ss.discretize(ball, method="visibility_field", uv=(4, 4), st=(4, 4))
        call = lambda: ss.reconstruct(field, huge)""",
    "impostor view": """
        imp = ss.discretize(ball, method="impostors", octree_depth=1, resolution=8)
        call = lambda: ss.reconstruct(imp, huge)""",
    "tradeoff grid": """
        knobs = {"octree_depth": list(range(1000)), "resolution": list(range(1000)),
                 "subdivisions": list(range(1000)), "fov": list(range(1000))}
        call = lambda: ss.tradeoff(ball, "impostors", knobs=knobs, camera=cam, progress=False)""",
}


@pytest.mark.parametrize("case", list(CASES))
def test_an_oversized_request_raises_and_the_process_survives(gpu, case):
    script = SETUP + textwrap.dedent(CASES[case]).strip() + "\n" + AFTER
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"exit code {r.returncode}: {r.stdout[-2000:]} {r.stderr[-3000:]}"
    assert "would take" in r.stdout, r.stdout


def test_the_limit_is_the_environment_s_when_set(tmp_path):
    """SCENESAMPLE_MEMORY_LIMIT moves the limit: a small request is refused under a tiny one."""
    script = (
        "import numpy as np, scenesample as ss\n"
        "o = np.zeros((1000, 3), np.float32); d = np.ones((1000, 3), np.float32)\n"
        "try:\n"
        "    ss.cast_rays(ss.scenes.icosphere(1), o, d, max_hits=8)\n"
        "except ss.InputError as e:\n"
        "    print(e)\n"
    )
    env = {"SCENESAMPLE_MEMORY_LIMIT": "100000", "PATH": "/usr/bin:/bin"}
    r = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300, env=env
    )
    assert r.returncode == 0, r.stderr
    assert "1000 rays x max_hits=8 would take 125.00 KiB" not in r.stdout
    assert "1000 rays x max_hits=8 would take 128000 bytes" in r.stdout, r.stdout
    assert "memory limit of 100000 bytes" in r.stdout, r.stdout
