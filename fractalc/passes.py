"""The channels of a render (docs/compositing.md): the default ones, which
every render has, and the passes that `aovs` adds. The kernel writes a
pixel's channels in this order (the EXR's), one float each."""
from __future__ import annotations

DEFAULT_CHANNELS = ("R", "G", "B", "A", "Z", "N.x", "N.y", "N.z", "steps")
# pass name (`--aov NAME`, `aovs=(NAME, ...)`) -> its channels, in channel order
PASSES = {
    "P": ("P.x", "P.y", "P.z"),
    "diffuse": ("diffuse.R", "diffuse.G", "diffuse.B"),
    "specular": ("specular.R", "specular.G", "specular.B"),
    "ao": ("ao",),
    "shadow": ("shadow",),
    "glow": ("glow.R", "glow.G", "glow.B"),
    "material": ("material",),
    "albedo": ("albedo.R", "albedo.G", "albedo.B"),
}
# the passes the direct renderer's shading fills in (`shade_passes`, stdlib_cl/shade.cl)
SHADING_PASSES = ("diffuse", "specular", "shadow", "ao")


def channels(aovs=()) -> tuple[str, ...]:
    """The channels of a render with the passes `aovs` (any order)."""
    unknown = sorted(set(aovs) - set(PASSES))
    if unknown:
        raise ValueError(f"unknown pass '{unknown[0]}' (known: {', '.join(PASSES)})")
    return DEFAULT_CHANNELS + tuple(c for name, names in PASSES.items() if name in aovs for c in names)
