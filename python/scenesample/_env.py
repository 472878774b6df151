"""Process environment the graphics stack reads, set once at import.

Mesa's Vulkan device-selection layer (``VK_LAYER_MESA_device_select``, installed with
``mesa-vulkan-drivers``) connects to a Wayland display while the Vulkan instance is created, to
learn which GPU drives the screen. On a headless machine (no ``WAYLAND_DISPLAY``, no
``XDG_RUNTIME_DIR``) libwayland then prints ``error: XDG_RUNTIME_DIR is invalid or not set in
the environment.`` twice: harmless (there is no screen to choose a GPU for, and the layer then
keeps the driver's own order), but it reads as an error. In exactly that case the layer is
turned off with ``NODEVICE_SELECT=1``, which Mesa documents for this purpose. A value the user
set is kept, and nothing changes where a display exists. Real driver errors still print.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping


def headless_vulkan(environ: MutableMapping[str, str] = os.environ) -> bool:
    """Turn off Mesa's device-selection layer when no display server can be reached; True
    when this call set ``NODEVICE_SELECT``."""
    if "NODEVICE_SELECT" in environ or environ.get("WAYLAND_DISPLAY") or environ.get("DISPLAY"):
        return False
    runtime = environ.get("XDG_RUNTIME_DIR")
    if runtime and os.path.isdir(runtime):
        return False
    environ["NODEVICE_SELECT"] = "1"
    return True


headless_vulkan()
