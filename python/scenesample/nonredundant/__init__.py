"""Non-redundant rendering (non-redundant-rendering.txt): conventional, non-redundant (§3) and
depth-peeled images, the surfaces rebuilt from them (§4, Algorithm 4) and soft shadows from
them (§5, Algorithm 5). The Rust side is ``src/nonredundant/``; the sampling metrics (§6.1.2)
are ``evaluate(images, scene, "sampling")``."""

from .._conventional import conventional
from .images import hybrid, mesh, nonredundant, peeling, points
from .shadows import AreaLight, ShadowResult, soft_shadows

__all__ = [
    "AreaLight",
    "ShadowResult",
    "conventional",
    "hybrid",
    "mesh",
    "nonredundant",
    "peeling",
    "points",
    "soft_shadows",
]
