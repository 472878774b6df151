"""A user's first minutes with an installed wheel, run from outside the source tree: import, load
a scene, cast rays, ask any-hit queries, make conventional images on whichever backend `auto`
picks and on the CPU, and (when there is an adapter) one GPU-only method."""

import sys
from pathlib import Path

import numpy as np
import scenesample as ss

root = Path(sys.argv[1]).resolve() if len(sys.argv) > 1 else None
here = Path(ss.__file__).resolve()
assert root is None or root not in here.parents, f"imported from the source tree: {here}"

scene = ss.scenes.shapes(seed=0, detail=1)
with_obj = Path(sys.argv[2]) if len(sys.argv) > 2 else None
if with_obj is not None and with_obj.exists():
    scene = ss.Scene.load(with_obj)
cam = ss.Camera.look_at(
    np.asarray(scene.bounds, np.float64).mean(0) + 2 * np.ptp(scene.bounds, axis=0),
    np.asarray(scene.bounds, np.float64).mean(0),
    yfov=0.8,
    width=96,
    height=64,
)
o, d = (a.reshape(-1, 3) for a in cam.pixel_rays())
hits = ss.cast_rays(scene, o, d)
assert (hits.triangle >= 0).any()
assert ss.occluded(scene, o, d).sum() == (hits.triangle >= 0).sum()
auto = ss.discretize(scene, cam)
cpu = ss.discretize(scene, cam, backend="cpu")
# The images follow the raster's fill rule where a pixel centre lies on an edge.
assert (cpu.triangle[0].ravel() == hits.triangle).mean() > 0.99
print(f"scenesample {here.parent}: {scene.triangle_count} triangles, auto chose {auto.backend}")
info = ss.device_info()
if not info["available"]:
    print(f"no GPU adapter: GPU-only methods skipped ({info['error']})")
else:
    nr = ss.discretize(scene, [cam, cam.with_resolution(96, 64)], "nonredundant")
    print(f"GPU: {info['name']}; nonredundant images {nr.depth.shape}")
print("smoke ok")
