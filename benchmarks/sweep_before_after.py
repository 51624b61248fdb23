"""Single-cell sweep times of the 500 x 500 reference scene (``bench_gibbs.py``), before and after.

In one process, interleaved (the fair comparison on a shared machine)::

    python benchmarks/sweep_before_after.py --interleaved

times ``CellGibbs.sample`` (heat bath) with the compiled sweep of this checkout (every cell's likelihood
ratio kept in fixed point, updated when a flip moves a ray's first or second hit; order and uniforms drawn
in compiled code) against the same kernel running the sweep as it was before the kept-sum rewrite ("sweep toward
the floor" (kept below: 16-byte pair records summed at every visit, a walk along the ray for every first
hit, torch's generator), alternating one sweep of each after 20 warm-up sweeps each, for the
systematic, permutation and random scans; both chains start from the same map. Prints the best and
the median of N sweeps (ms) of each, their ratio, the load average, and the floor *of the pair-summing
sweep*: one pass over the same 100 MB of pair records (alone, and with the gather of every pair's ray
record, in systematic and in random order); the kept-sum sweep reads no pair at a visit, so it can go
below it. :func:`interleaved` is what ``bench_gibbs.py`` calls.

For the code in another checkout (one after the other, so only on a quiet machine)::

    git worktree add /tmp/before 3967c49
    python benchmarks/sweep_before_after.py /tmp/before
    python benchmarks/sweep_before_after.py .

prints the best and the median of 15 sweeps (ms), after 20 warm-up sweeps, for the systematic,
permutation and random scans, heat bath. Works with
the flat (older) and the role-grouped ``ogm_ppl.inference`` layout.
"""

from __future__ import annotations

import math
import os
import sys
from typing import NamedTuple

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numba as nb
import numpy as np

SCANS = ("systematic", "permutation", "random")


def main(root: str, repeat: int = 15) -> dict:
    root = os.path.abspath(root)
    sys.path.insert(0, root)
    sys.path.insert(0, os.path.join(root, "benchmarks"))
    import ogm_ppl

    if not ogm_ppl.__file__.startswith(root):
        raise SystemExit(f"imported {ogm_ppl.__file__}, not the checkout at {root}")
    from bench_gibbs import build

    try:
        from ogm_ppl.inference.mcmc.gibbs import CellGibbs
    except ImportError:  # the older flat layout
        from ogm_ppl.inference.gibbs import CellGibbs  # type: ignore[no-redef]
    import time

    import torch

    model = build(500, 100)
    out = {}
    for scan in SCANS:
        torch.manual_seed(0)
        k = CellGibbs(model, scan=scan)
        k.setup()
        p = k.current_params()
        times = []
        for i in range(20 + repeat):  # 20 warm-up sweeps, as in interleaved()
            t = time.perf_counter()
            p = k.sample(p)
            if i >= 20:
                times.append(time.perf_counter() - t)
        out[scan] = {
            "best": 1e3 * min(times),
            "median": 1e3 * float(np.median(times)),
            "change rate": k.diagnostics()["change rate"],
        }
        if getattr(k, "_bits", None) is not None:  # the kept-sum kernel: its fixed point and rounding bound
            out["fixed-point bits"] = k._bits
            out["rounding bound"] = int(np.diff(k._c_off).max()) * 2.0**-k._bits
    print(
        root,
        "  ".join(
            f"{k} best {v['best']:.1f} / median {v['median']:.1f} ms (change rate {v['change rate']:.3f})"
            for k, v in out.items()
            if k in SCANS
        ),
    )
    if "fixed-point bits" in out:
        print(
            f"fixed-point bits S = {out['fixed-point bits']}; log-odds within {out['rounding bound']:.2g} of the "
            "floating-point sum (the most rays a cell has x 2^-S)"
        )
    return out


# ----------------------------------------------------------------------------------------------------
# The baseline: the compiled single-cell sweep before the kept-sum rewrite (commit 9f68076), verbatim but
# for names (heat bath, independent prior: the reference scene's), and a CellGibbs that runs it.
_BASE_PAIR = np.dtype([("ll", np.float64), ("ray", np.int32), ("kappa", np.int32)], align=True)
_BASE_RAY = np.dtype([("ll_hit", np.float64), ("f", np.int64)], align=True)


class _BaseState(NamedTuple):
    m: np.ndarray
    rays: np.ndarray
    offsets: np.ndarray
    cells: np.ndarray
    c_off: np.ndarray
    pairs: np.ndarray
    ll: np.ndarray


@nb.njit(cache=True, inline="always")
def _base_next_occupied(st, r, start):
    a = st.offsets[r]
    n = st.offsets[r + 1] - a
    for j in range(start, n):
        if st.m[st.cells[a + j]]:
            return j
    return n


@nb.njit(cache=True)
def _base_log_lik_ratio(st, k):
    d = 0.0
    pairs = st.pairs
    rays = st.rays
    for p in range(st.c_off[k], st.c_off[k + 1]):
        kap = pairs[p].kappa
        r = pairs[p].ray
        fr = rays[r].f
        if fr < kap:
            continue
        if fr > kap:
            t = pairs[p].ll - rays[r].ll_hit
        else:
            t = pairs[p].ll - st.ll[r, _base_next_occupied(st, r, kap + 1)]
        if t == t:
            d += t
    return d


@nb.njit(cache=True)
def _base_set_cell(st, k, v):
    if st.m[k] == v:
        return
    st.m[k] = v
    pairs = st.pairs
    rays = st.rays
    for p in range(st.c_off[k], st.c_off[k + 1]):
        kap = pairs[p].kappa
        r = pairs[p].ray
        if v:
            if kap < rays[r].f:
                rays[r].f = kap
                rays[r].ll_hit = pairs[p].ll
        elif rays[r].f == kap:
            n = _base_next_occupied(st, r, kap + 1)
            rays[r].f = n
            rays[r].ll_hit = st.ll[r, n]


@nb.njit(cache=True, inline="always")
def _base_new_value(lo, u, cur):
    if lo != lo:
        return 1 if u < 0.5 else 0
    if lo >= 0.0:
        return 1 if u * (1.0 + math.exp(-lo)) < 1.0 else 0
    e = math.exp(lo)
    return 1 if u * (1.0 + e) < e else 0


@nb.njit(cache=True)
def _base_sweep(st, order, prior_log_odds, uniforms):
    flips = 0
    for i in range(order.shape[0]):
        k = order[i]
        lo = prior_log_odds[k] + _base_log_lik_ratio(st, k)
        v = _base_new_value(lo, uniforms[i], st.m[k])
        if v != st.m[k]:
            _base_set_cell(st, k, v)
            flips += 1
    return flips


def _baseline():
    from ogm_ppl.inference.mcmc.gibbs import CellGibbs
    from ogm_ppl.inference.mcmc.kernel import MapKernel

    class BaselineCellGibbs(CellGibbs):
        """:class:`CellGibbs` (heat bath, independent prior) running the sweep before the kept-sum rewrite."""

        def _set_up(self) -> None:
            super()._set_up()
            pairs = np.empty(len(self._c_ray), _BASE_PAIR)
            pairs["ll"], pairs["ray"], pairs["kappa"] = self._ll[self._c_ray, self._c_kappa], self._c_ray, self._c_kappa
            self._base_pairs = pairs

        def _set_state(self, m) -> None:
            MapKernel._set_state(self, m)  # the map and every ray's first hit
            f = self.first_hit_state
            rays = np.empty(len(f), _BASE_RAY)
            rays["f"], rays["ll_hit"] = f, self._ll[np.arange(len(f)), f]
            arrays = (self._offsets, self._cells, self._c_off, self._base_pairs, self._ll)
            self._base = _BaseState(self.state, rays, *arrays)
            self.chain.f = rays["f"]

        def _sweep(self) -> int:
            assert self._prior_lo is not None and self.update == "gibbs"
            order = self._order(self._visit)  # torch's generator, as before
            u = self._uniforms(len(order))
            self.chain.updates += len(order)
            return _base_sweep(self._base, order, self._prior_lo, u)

    return BaselineCellGibbs


def interleaved(model, repeat: int = 7, scans=SCANS, warmup: int = 20) -> dict:
    """Best-of-``repeat`` (and median) ``sample`` times (seconds) of :class:`CellGibbs` and of the baseline kernel, one
    sweep of each in turn after ``warmup`` sweeps each (the chains' steady state: nearly all of a long
    chain's sweeps are like these; the first sweeps from the OGM map move more cells), per scan; both start
    from the same map (the thresholded OGM). Returns ``{scan: {"before": s, "after": s, "ratio": before / after,
    "before_median": s, "after_median": s}}`` and the load
    average (``/proc/loadavg``, where there is one) at the start and at the end."""
    import time

    import torch

    from ogm_ppl.inference.mcmc.gibbs import CellGibbs

    Baseline = _baseline()
    out: dict = {"loadavg_start": _loadavg()}
    for scan in scans:
        pair = {}
        for name, cls in (("before", Baseline), ("after", CellGibbs)):
            torch.manual_seed(0)
            k = cls(model, scan=scan)
            k.setup()
            p = k.current_params()
            for _ in range(warmup):  # past the first sweeps from the OGM map, where most cells still move
                p = k.sample(p)
            pair[name] = [k, p, []]
        for _ in range(repeat):
            for entry in pair.values():
                t = time.perf_counter()
                entry[1] = entry[0].sample(entry[1])
                entry[2].append(time.perf_counter() - t)
        b, a = min(pair["before"][2]), min(pair["after"][2])
        bm, am = float(np.median(pair["before"][2])), float(np.median(pair["after"][2]))
        out[scan] = {"before": b, "after": a, "ratio": b / a, "before_median": bm, "after_median": am}
    out["loadavg_end"] = _loadavg()
    return out


def floors(model, repeat: int = 7) -> dict:
    """The floor of a sweep that sums every cell's rays (the "before" kernel's and the kept-sum sweep's earlier
    ones): best-of-``repeat`` times (seconds) of one pass over the pair records (16 bytes a (ray, cell)
    pair, by cell): ``"stream"`` sums their likelihoods; ``"stream + rays, systematic"`` also reads every
    pair's ray record, cell by cell in the systematic scan's order, and ``"... random"`` in a random
    scan's order. The kept-sum sweep of this checkout reads no pairs at a visit, so it can go below it."""
    import time

    @nb.njit
    def stream(pairs):
        s = 0.0
        for p in range(pairs.shape[0]):
            s += pairs[p].ll
        return s

    @nb.njit
    def gather(st, order):
        s = 0.0
        pairs, rays, c_off = st.pairs, st.rays, st.c_off
        for i in range(order.shape[0]):
            k = order[i]
            d = 0.0
            for p in range(np.uint64(c_off[k]), np.uint64(c_off[k + 1])):
                d += pairs[p].ll - rays[np.uint64(pairs[p].ray)].ll_hit
            s += d
        return s

    k = _baseline()(model)
    k.setup()
    st = k._base
    latent = k._latent
    rand = np.ascontiguousarray(latent[np.random.default_rng(0).integers(0, len(latent), len(latent))])
    runs = {
        "stream": lambda: stream(st.pairs),
        "stream + rays, systematic": lambda: gather(st, latent),
        "stream + rays, random": lambda: gather(st, rand),
    }
    best = {}
    for name, fn in runs.items():
        fn()
        best[name] = float("inf")
        for _ in range(repeat):
            t = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - t)
    best["bytes"] = st.pairs.nbytes
    return best


def _loadavg() -> str:
    try:
        with open("/proc/loadavg") as fh:
            return " ".join(fh.read().split()[:3])
    except OSError:
        return "n/a"


def report(res: dict, floor: dict | None = None) -> None:
    print(
        f"single-cell sweep, best of N, interleaved in one process (load average {res['loadavg_start']} -> "
        f"{res['loadavg_end']}):"
    )
    for scan in SCANS:
        if scan in res:
            r = res[scan]
            print(
                f"  {scan:<12} before {r['before'] * 1e3:7.1f} ms   after {r['after'] * 1e3:6.1f} ms   "
                f"{r['ratio']:4.1f}x   (medians {r['before_median'] * 1e3:.1f} -> {r['after_median'] * 1e3:.1f} ms)"
            )
    if floor:
        print(
            f"  floor: one pass over the {floor['bytes'] / 1e6:.0f} MB of pair records "
            f"{floor['stream'] * 1e3:.1f} ms; with the ray records, systematic order "
            f"{floor['stream + rays, systematic'] * 1e3:.1f} ms, random order "
            f"{floor['stream + rays, random'] * 1e3:.1f} ms"
        )


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    if len(sys.argv) > 1 and sys.argv[1] == "--interleaved":
        sys.path.insert(0, os.path.dirname(__file__))
        from bench_gibbs import build

        mdl = build(500, 100)
        report(interleaved(mdl, repeat=int(sys.argv[2]) if len(sys.argv) > 2 else 9), floors(mdl))
    else:
        main(sys.argv[1] if len(sys.argv) > 1 else ".")
