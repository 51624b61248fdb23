"""Patch maps (Chapter 3): online and offline, each patch's posterior given the rays through it."""

from ogm_ppl.inference.patch_map.maps import (
    PatchMap,
    offline_patch_map,
    online_patch_map,
    reference_map,
)
from ogm_ppl.inference.tiling import centred_patches, tile_patches

__all__ = [
    "PatchMap",
    "online_patch_map",
    "offline_patch_map",
    "reference_map",
    "tile_patches",
    "centred_patches",
]
