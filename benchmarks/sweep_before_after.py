"""Single-cell sweep times of the 500 x 500 reference scene (``bench_gibbs.py``) for the code in a given
checkout, so that two versions can be timed in the same session:

    git worktree add /tmp/before 3967c49
    python benchmarks/sweep_before_after.py /tmp/before
    python benchmarks/sweep_before_after.py .

Prints the best of 7 sweeps (ms) for the systematic, permutation and random scans, heat bath. Works with
the flat (before issue 12) and the role-grouped ``ogm_ppl.inference`` layout.
"""

from __future__ import annotations

import os
import sys

os.environ.setdefault("NUMBA_NUM_THREADS", "1")


def main(root: str) -> dict:
    root = os.path.abspath(root)
    sys.path.insert(0, root)
    sys.path.insert(0, os.path.join(root, "benchmarks"))
    import ogm_ppl

    if not ogm_ppl.__file__.startswith(root):
        raise SystemExit(f"imported {ogm_ppl.__file__}, not the checkout at {root}")
    from bench_gibbs import build, sweep_time

    try:
        from ogm_ppl.inference.mcmc.gibbs import CellGibbs
    except ImportError:  # the layout before issue 12
        from ogm_ppl.inference.gibbs import CellGibbs  # type: ignore[no-redef]
    model = build(500, 100)
    out = {scan: 1e3 * sweep_time(CellGibbs(model, scan=scan), repeat=7) for scan in ("systematic", "permutation", "random")}
    print(root, "  ".join(f"{k} {v:.1f} ms" for k, v in out.items()))
    return out


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
