"""Eye-based point rendering (eye-based-point-rendering.txt): EPR and iVIR points (§3.1-3.4),
splatting into many views (§3.5), reflections (§4) and omnidirectional soft shadows (§5), each
beside MVR and iVIR. The Rust side is ``src/epr/``."""

from .omni import OmniShadowResult, omni_shadows
from .points import (
    Points,
    Reflector,
    SplatBuffers,
    cube_resolution,
    epr_points,
    reflectors_of,
    splat,
)
from .reflections import ReflectionResult, reflection_reference, reflections

__all__ = [
    "OmniShadowResult",
    "Points",
    "ReflectionResult",
    "Reflector",
    "SplatBuffers",
    "cube_resolution",
    "epr_points",
    "omni_shadows",
    "reflection_reference",
    "reflections",
    "reflectors_of",
    "splat",
]
