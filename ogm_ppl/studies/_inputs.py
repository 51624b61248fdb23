"""What the studies of this package share: option checks that name the option, the map files
of an experiment's output folder, and float64 work.

An experiment folder is what ``ogm-ppl experiment SPEC --out DIR`` writes with ``[output] maps = true``:
``DIR/datasets/<dataset>.eval.npz`` (the truth and the touched cells of each dataset) and
``DIR/maps/<dataset>/<algorithm>.npz`` (each algorithm's ``marginals``) with ``<algorithm>.json`` (its scores).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl._dtype import float64
from ogm_ppl.studies.errors import StudyInputError, StudyOptionError

__all__ = ["check_int", "check_positive", "float64", "maps_folders", "npz_array"]


def check_int(value: Any, option: str, lo: int, hi: int | None = None) -> int:
    """``value`` as an int in ``lo..hi`` (``hi`` None: no upper limit), else :class:`StudyOptionError`."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise StudyOptionError(option, f"must be a whole number, got {value!r}")
    v = int(value)
    if v < lo or (hi is not None and v > hi):
        limit = f"at least {lo}" if hi is None else f"between {lo} and {hi}"
        raise StudyOptionError(option, f"must be {limit}, got {v}")
    return v


def check_positive(value: Any, option: str) -> float:
    """``value`` as a finite float above 0, else :class:`StudyOptionError`."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise StudyOptionError(option, f"must be a number, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise StudyOptionError(option, f"must be positive and finite, got {v}")
    return v


def npz_array(path: Path, key: str, kind: str) -> np.ndarray:
    """The array ``key`` of the ``.npz`` file ``path``, flattened (no pickles). A missing file is a
    :class:`FileNotFoundError` naming ``kind`` (what the file should be), a missing key a
    :class:`StudyInputError` listing the keys there."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing ({kind})")
    with np.load(path, allow_pickle=False) as z:
        if key not in z:
            raise StudyInputError(f"{path}: no {key!r} array (keys {sorted(z.keys())})")
        return np.asarray(z[key]).reshape(-1)


def maps_folders(out_dir: Path) -> list[Path]:
    """The dataset folders of ``out_dir/maps`` (sorted); :class:`FileNotFoundError` if there is no such folder
    or it holds none."""
    maps = out_dir / "maps"
    if not maps.is_dir():
        raise FileNotFoundError(f"{maps}: no maps folder (run the experiment with [output] maps = true)")
    folders = sorted(p for p in maps.iterdir() if p.is_dir())
    if not folders:
        raise FileNotFoundError(f"{maps}: no dataset folders")
    return folders
