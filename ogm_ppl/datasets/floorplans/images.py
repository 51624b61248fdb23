r"""The corpora stored as images: ``houseexpo`` (100 HouseExpo renderings), ``ipa`` (IPA room-segmentation maps)
and ``dungeon`` (DungeonMaps, PNGs inside one tar.gz).

Each pixel is classified occupied / free / unknown here; :func:`~ogm_ppl.datasets.floorplans._core.rasterise`
then makes the grid (the steps of :mod:`ogm_ppl.datasets.floorplans`).

* HouseExpo: grey >= 128 is free (inside the house), the rest occupied (wall *or outside*); 1 px = 1 cm.
* IPA: converted to grey; the background grey (the most common value on the image border, when it is neither
  black nor white) +-3 is unknown, the rest is thresholded at 128; 0.05 m/px.
* DungeonMaps: RGB (127,127,127) = obstacle/outside, (195,195,194) = free, (255,216,0) = robot start (free); any
  other colour is an error naming the archive member. No metric scale.
"""

from __future__ import annotations

import io
import tarfile
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.floorplans._core import corpus_path, floorplan_root, natural_key

__all__ = [
    "DUNGEON_TAR",
    "HOUSEEXPO_DIR",
    "IPA_DIR",
    "classify_ipa",
    "dungeon_bytes",
    "dungeon_pixels",
    "list_image_plans",
    "open_image",
    "plan_image_path",
    "plan_pixels",
]

DUNGEON_TAR = "dungeonmaps-synthetic/DungeonMaps_subset_train2000_test500.tar.gz"
HOUSEEXPO_DIR = "houseexpo-subset100/png"
IPA_DIR = "ipa-room-segmentation-maps/test_maps"


@lru_cache(maxsize=8)
def _dungeon_members(tar_path: str) -> dict[str, str]:
    """Plan name (``train/762``, ``test/img_6296``) -> tar member name."""
    try:
        with tarfile.open(tar_path, "r:gz") as tf:
            names = tf.getnames()
    except (OSError, tarfile.TarError) as e:
        raise ValueError(f"{tar_path}: unreadable DungeonMaps archive ({e})") from e
    out = {}
    for m in names:
        parts = m.split("/")
        if len(parts) == 3 and parts[1] in ("train", "test") and parts[2].endswith(".png"):
            out[f"{parts[1]}/{parts[2][:-4]}"] = m
    return out


def list_image_plans(corpus: str, root=None) -> list[str]:
    """All plan names of ``houseexpo``, ``ipa`` or ``dungeon``, sorted (natural order). IPA's
    ``*_gt_segmentation`` images are not maps and are left out."""
    base = floorplan_root(root)
    if corpus == "houseexpo":
        d = corpus_path(base / HOUSEEXPO_DIR, corpus)
        return sorted((p.stem for p in d.glob("*.png")), key=natural_key)
    if corpus == "ipa":
        d = corpus_path(base / IPA_DIR, corpus)
        files = [p for p in d.iterdir() if p.suffix in (".png", ".pgm") and "_gt_segmentation" not in p.stem]
        return sorted((p.stem for p in files), key=natural_key)
    return sorted(_dungeon_members(str(corpus_path(base / DUNGEON_TAR, corpus))), key=natural_key)


def open_image(data_or_path, where: str):
    """A PIL image, fully loaded, from bytes or a path; ``ValueError`` naming ``where`` when unreadable."""
    from PIL import Image

    try:
        im = Image.open(io.BytesIO(data_or_path) if isinstance(data_or_path, bytes) else data_or_path)
        im.load()
    except Exception as e:
        raise ValueError(f"{where}: unreadable image ({type(e).__name__}: {e})") from e
    return im


def _classify_binary(im) -> tuple[np.ndarray, np.ndarray]:
    """HouseExpo: grey >= 128 free, else occupied (wall or outside)."""
    g = np.asarray(im.convert("L"))
    free = g >= 128
    return ~free, free


def classify_ipa(im) -> tuple[np.ndarray, np.ndarray]:
    """``(occupied, free)`` pixels of a grey plan image: the border's most common grey (neither black nor white)
    +-3 is unknown, the rest thresholded at 128."""
    g = np.asarray(im.convert("L")).astype(np.int16)
    edge = np.concatenate([g[0], g[-1], g[:, 0], g[:, -1]])
    bg = int(np.bincount(edge).argmax())
    unknown = np.zeros(g.shape, dtype=bool)
    if 20 < bg < 235:
        unknown = np.abs(g - bg) <= 3
    occ = (g < 128) & ~unknown
    free = (g >= 128) & ~unknown
    return occ, free


_DUNGEON_COLOURS = {(127, 127, 127): "occ", (195, 195, 194): "free", (255, 216, 0): "free"}


def dungeon_pixels(im, where: str) -> tuple[np.ndarray, np.ndarray]:
    """``(occupied, free)`` pixels of a DungeonMaps image; other colours are an error naming ``where``."""
    rgb = np.asarray(im.convert("RGB")).astype(np.int32)
    key = (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]
    occ = key == (127 << 16 | 127 << 8 | 127)
    free = (key == (195 << 16 | 195 << 8 | 194)) | (key == (255 << 16 | 216 << 8 | 0))
    if not (occ | free).all():
        bad = np.unique(rgb[~(occ | free)].reshape(-1, 3), axis=0)[:3].tolist()
        raise ValueError(f"{where}: unexpected colours {bad} (DungeonMaps has exactly {list(_DUNGEON_COLOURS)})")
    return occ, free


def plan_image_path(corpus: str, name: str, root=None) -> Path:
    """The image file of a HouseExpo or IPA plan (DungeonMaps live inside one archive: ``KeyError``)."""
    base = floorplan_root(root)
    if corpus == "houseexpo":
        path = base / HOUSEEXPO_DIR / f"{name}.png"
        if not path.is_file():
            raise KeyError(f"no HouseExpo plan {name!r} under {path.parent}")
        return path
    if corpus == "ipa":
        d = base / IPA_DIR
        found = next((d / f"{name}{ext}" for ext in (".png", ".pgm") if (d / f"{name}{ext}").is_file()), None)
        if found is None:
            raise KeyError(f"no IPA plan {name!r} under {d}")
        return found
    raise KeyError(f"{corpus} plans are not image files")


def plan_pixels(corpus: str, name: str, root=None) -> tuple[np.ndarray, np.ndarray]:
    """``(occupied, free)`` pixels of one plan of an image corpus."""
    if corpus in ("houseexpo", "ipa"):
        path = plan_image_path(corpus, name, root)
        classify = _classify_binary if corpus == "houseexpo" else classify_ipa
        return classify(open_image(path, str(path)))
    data, where = dungeon_bytes([name], root)[name]
    return dungeon_pixels(open_image(data, where), where)


def dungeon_bytes(names: Sequence[str], root=None) -> dict[str, tuple[bytes, str]]:
    """The PNG bytes of the named DungeonMaps, read in one pass over the archive (no extraction to disk)."""
    tar_path = str(corpus_path(floorplan_root(root) / DUNGEON_TAR, "dungeon"))
    members = _dungeon_members(tar_path)
    wanted = {}
    for n in names:
        if n not in members:
            raise KeyError(f"no DungeonMaps plan {n!r} in {tar_path}")
        wanted[members[n]] = n
    out = {}
    with tarfile.open(tar_path, "r:gz") as tf:
        for info in tf:
            if info.name in wanted:
                where = f"{tar_path}!{info.name}"
                f = tf.extractfile(info)
                if f is None:
                    raise ValueError(f"{where}: not a regular file")
                out[wanted[info.name]] = (f.read(), where)
                if len(out) == len(wanted):
                    break
    return out
