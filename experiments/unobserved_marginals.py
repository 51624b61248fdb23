"""Mean marginal of the never-observed cells of each map an experiment wrote, per algorithm and dataset.

A cell is never observed when traditional OGM leaves it at its prior, ``q = 0.5`` (the ``ogm`` algorithm of
the spec, with ``prior = 0.5``). What a prior predicts there, far from every ray, decides the "all cells"
scores of Table 6.4 on maps with a large unobserved exterior.

    python experiments/unobserved_marginals.py out/experiments/table_6_4_tempered
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def marginals(path: Path) -> np.ndarray:
    """The ``marginals`` array of a map file an experiment wrote (refused with the path if absent)."""
    with np.load(path, allow_pickle=False) as z:
        if "marginals" not in z:
            raise ValueError(f"{path}: no 'marginals' array (keys {sorted(z.keys())})")
        return np.asarray(z["marginals"], dtype=np.float64).reshape(-1)


def unobserved_means(out_dir: Path, baseline: str = "ogm") -> dict[str, dict[str, float]]:
    """``{algorithm: {dataset: mean marginal over the cells the baseline leaves at 0.5}}``."""
    maps = out_dir / "maps"
    if not maps.is_dir():
        raise FileNotFoundError(f"{maps}: no maps folder (run the experiment with [output] maps = true)")
    res: dict[str, dict[str, float]] = {}
    for d in sorted(p for p in maps.iterdir() if p.is_dir()):
        base = d / f"{baseline}.npz"
        if not base.exists():
            raise FileNotFoundError(f"{base}: the baseline map is missing")
        never = marginals(base) == 0.5
        for f in sorted(d.glob("*.npz")):
            q = marginals(f)
            if q.shape != never.shape:
                raise ValueError(f"{f}: {q.size} cells, the baseline has {never.size}")
            res.setdefault(f.stem, {})[d.name] = float(q[never].mean()) if never.any() else float("nan")
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path, help="an experiment's output folder (holding maps/)")
    ap.add_argument("--baseline", default="ogm", help="the traditional-OGM algorithm of the spec")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    a = ap.parse_args(argv)
    res = unobserved_means(a.out_dir, a.baseline)
    if a.json:
        print(json.dumps(res, indent=1))
        return 0
    for alg, per in res.items():
        v = np.array(list(per.values()))
        print(
            f"{alg:>24}: mean {np.nanmean(v):.3f}, range {np.nanmin(v):.2f}-{np.nanmax(v):.2f} over {len(v)} datasets"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
