"""Compile time of a sweep kernel with numba's own inliner and with :mod:`ogm_ppl._numba_inline` (one deep-copy
memo per callee, one copy).

Each measurement is a fresh process with an empty numba cache (``NUMBA_CACHE_DIR`` in a temporary folder) that
compiles one specialisation: the single-cell sweep :func:`~ogm_ppl.inference._kernels.cell_sweep.sweep` with an
independent prior (:class:`~ogm_ppl.priors.compiled.independent.IndependentCells`), the kernel whose nested inlined
helpers (the prior's conditional, the state update and its ray walk) made it the costliest compile of the test
suite. The child reports its CPU seconds (``time.process_time``, so a loaded machine changes them less than wall
seconds); ``--repeat`` alternates the two ways and keeps each one's best. The ratio is numba's own over ours.

Writes ``out/bench/bench_numba_inline.json``; about a minute on a quiet core (``--repeat 1``). Measured here (2 cores,
load 6-9): numba 42.6 s, ours 15.0 s CPU, 2.8x.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))
from _common import write_json
from bench_table_6_6 import loadavg

CHILD = """
import sys, time
import numpy as np
from numba.core import inline_closurecall
from ogm_ppl import _numba_inline
if sys.argv[1] == "numba":
    inline_closurecall.InlineWorker.inline_ir = _numba_inline.ORIGINAL_INLINE_IR
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.priors.compiled.independent import independent_cells
i64 = lambda n: np.zeros(n, np.int64)
st = cs.CellState(np.zeros(4, np.uint8), np.zeros(2, cs.RAY), i64(4), np.zeros(4, cs.INF), False, i64(3), i64(3),
                  i64(5), i64(5), np.zeros(3, np.int32), np.zeros((2, 3)), 1.0)
t0 = time.process_time()
cs.sweep(st, i64(0), independent_cells(np.zeros(4)), np.zeros(0), cs.HEAT_BATH)
print(time.process_time() - t0)
"""


def compile_seconds(way: str) -> float:
    """CPU seconds of one cold compile of the sweep in a fresh process (``way``: ``"numba"`` or ``"ours"``)."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        out = subprocess.run([sys.executable, "-c", CHILD, way], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.split()[-1])


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeat", type=int, default=1, help="compiles of each way (alternating); the best is kept")
    args = p.parse_args(argv)
    load_before = loadavg()
    times: dict[str, list[float]] = {"numba": [], "ours": []}
    for _ in range(args.repeat):
        for way in times:
            times[way].append(compile_seconds(way))
            print(f"{way}: {times[way][-1]:.1f} s CPU", flush=True)
    best = {way: min(t) for way, t in times.items()}
    ratio = best["numba"] / best["ours"]
    print(
        f"cell_sweep.sweep (IndependentCells), cold compile: numba's inliner {best['numba']:.1f} s, ours "
        f"{best['ours']:.1f} s CPU: {ratio:.2f}x faster (load {load_before} -> {loadavg()})"
    )
    write_json(
        "bench_numba_inline",
        {
            "kernel": "cell_sweep.sweep(IndependentCells)",
            "cpu_seconds": times,
            "best": best,
            "ratio": ratio,
            "load_before": load_before,
            "load_after": loadavg(),
        },
    )


if __name__ == "__main__":
    main()
