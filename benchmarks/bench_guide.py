"""The corpus guide's map on the CPU: one pass and the symmetrised map (8 turns and flips) of a ~1.4 M-cell map.

Scene: the sparse scene of the other benchmarks (5 cm cells, 75-cell range, sigma 3 cells) grown to
``--side`` x ``--side`` cells (default 1184: 1.40 M cells, a 59 x 59 m log's map), its features
(:func:`~ogm_ppl.inference.variational.amortised_features.evidence_features`, timed once) fed to the headline's
corpus guide (``houseexpo+ipa``: 6 dilated 3 x 3 convolutions of 24 channels, 27,463 multiply-adds a cell).

Compared in the same run, on ``--threads`` threads (default 2):
  baseline   the reference network, ``GuideNet.forward`` and ``_symmetrised`` (NCHW, the grid turned 8 times)
  fast       :func:`~ogm_ppl.inference.variational.amortised_fast.fast_logits` (channels-last, fused
             convolution + ReLU, the symmetries as turned kernels, side by side on one thread each), what
             ``AmortisedGuide.marginals`` runs; and its symmetrised map with the 8 passes one after another

Printed: seconds per million cells for one pass and the symmetrised map, the ratios, the maximum difference of
the logits, the GFLOP/s (2 x multiply-adds / s) against the machine's measured rates in the same run (a plain
large convolution, 256 -> 256 channels 3 x 3, channels-last: the "peak"; and one 24 -> 24 3 x 3 convolution with
ReLU as the fast path runs it, over the same map: the rate of these shapes), and the fast path's time by layer.

    python benchmarks/bench_guide.py [--side 1184] [--threads 2] [--repeat 2]   (writes out/bench/bench_guide.json)
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import best_time, peak_rss_mb, sparse_scene, write_json

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.inference.variational.amortised_fast import _FUSED, _conv_relu, _pointwise, fast_logits
from ogm_ppl.inference.variational.amortised_features import evidence_features
from ogm_ppl.inference.variational.amortised_net import _symmetrised
from ogm_ppl.inference.variational.corpus_guides import corpus_guide
from ogm_ppl.priors import IndependentPrior

GUIDE = "houseexpo+ipa"


def macs_per_cell(net) -> int:
    """Multiply-adds a cell of one pass: every convolution's ``O x I x kh x kw`` (head and skip included)."""
    convs = [*net.convs, net.head, net.skip]
    return sum(int(c.weight.numel()) for c in convs)


def features(side: int, poses: int):
    grid, scans = sparse_scene(side, poses, walls=side * side // 6000, beams=360)
    rays = raycast(grid, scans)
    model = OccupancyModel(grid, rays, GaussianRange(3.0), IndependentPrior(0.5, grid.num_cells))
    t = time.perf_counter()
    arch = corpus_guide(GUIDE).arch
    x = evidence_features(model, None, arch.delta, arch.phase)[None]
    return x, time.perf_counter() - t


def peak_rates(side: int, repeat: int) -> dict:
    """GFLOP/s of a plain large convolution and of one 24 -> 24 3 x 3 convolution with ReLU over the map."""
    with torch.inference_mode():
        big = torch.rand(1, 256, 128, 128).contiguous(memory_format=torch.channels_last)
        wb = torch.rand(256, 256, 3, 3).contiguous(memory_format=torch.channels_last)
        t_big = best_time(lambda: torch.nn.functional.conv2d(big, wb, padding=1), repeat)
        h = torch.rand(1, 24, side, side).contiguous(memory_format=torch.channels_last)
        w = torch.rand(24, 24, 3, 3).contiguous(memory_format=torch.channels_last)
        b = torch.rand(24)
        t_24 = best_time(lambda: _conv_relu(h, w, b, 1, _FUSED), repeat)
    return {
        "plain_conv_256x256_3x3_gflops": 2 * wb.numel() * 128 * 128 / t_big / 1e9,
        "conv_24x24_3x3_relu_gflops": 2 * w.numel() * side * side / t_24 / 1e9,
    }


def layer_times(net, x: torch.Tensor) -> list[dict]:
    """The fast path's time by layer (one pass)."""
    rows = []
    with torch.inference_mode():
        h = x.contiguous(memory_format=torch.channels_last)
        for i, c in enumerate(net.convs):
            w = c.weight.detach().contiguous(memory_format=torch.channels_last)
            d = int(c.dilation[0])
            t = time.perf_counter()
            h = _conv_relu(h, w, c.bias.detach(), d, _FUSED)
            dt = time.perf_counter() - t
            rows.append(
                {
                    "layer": f"conv{i} {c.in_channels}->{c.out_channels} d{d}",
                    "s": dt,
                    "gflops": 2 * w.numel() * x.shape[-1] * x.shape[-2] / dt / 1e9,
                }
            )
        t = time.perf_counter()
        _pointwise(h, net.head) + _pointwise(x.contiguous(memory_format=torch.channels_last), net.skip)
        rows.append({"layer": "head + skip", "s": time.perf_counter() - t, "gflops": float("nan")})
    return rows


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--side", type=int, default=1184)
    ap.add_argument("--poses", type=int, default=300)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    net = corpus_guide(GUIDE).net.eval()
    x, t_feat = features(a.side, a.poses)
    cells = x.shape[-1] * x.shape[-2]
    mcells = cells / 1e6
    flop = 2 * macs_per_cell(net) * cells
    print(
        f"{a.side} x {a.side} = {cells:,} cells, {macs_per_cell(net):,} multiply-adds a cell, "
        f"{a.threads} threads, load {os.getloadavg()[0]:.2f}; features {t_feat:.2f} s"
    )

    def timed(fn):
        t = time.perf_counter()
        out = fn()
        return out, time.perf_counter() - t

    with torch.no_grad():  # the first calls (warm-up) give the maps compared; the baseline's are long, so few
        base1, _ = timed(lambda: net(x))
        t_base1 = best_time(lambda: net(x), 1, 0)
        fast1, _ = timed(lambda: fast_logits(net, x))
        t_fast1 = best_time(lambda: fast_logits(net, x), a.repeat, 0)
        base8, t_base8 = timed(lambda: _symmetrised(net, x))
        fast8, t_fast8 = timed(lambda: fast_logits(net, x, True))
        if a.repeat > 1:
            t_fast8 = min(t_fast8, best_time(lambda: fast_logits(net, x, True), a.repeat - 1, 0))
        t_serial8 = best_time(lambda: fast_logits(net, x, True, parallel=False), 1, 0)
    peaks = peak_rates(min(a.side, 512), a.repeat + 1)
    layers = layer_times(net, x)
    res = {
        "side": a.side,
        "cells": cells,
        "threads": a.threads,
        "macs_per_cell": macs_per_cell(net),
        "load_1min": os.getloadavg()[0],
        "fused_conv_relu": _FUSED,
        "features_s": t_feat,
        "one_pass": {
            "baseline_s": t_base1,
            "fast_s": t_fast1,
            "baseline_s_per_mcell": t_base1 / mcells,
            "fast_s_per_mcell": t_fast1 / mcells,
            "speedup": t_base1 / t_fast1,
            "baseline_gflops": flop / t_base1 / 1e9,
            "fast_gflops": flop / t_fast1 / 1e9,
            "max_abs_diff": float((base1 - fast1).abs().max()),
        },
        "symmetrised": {
            "baseline_s": t_base8,
            "fast_s": t_fast8,
            "baseline_s_per_mcell": t_base8 / mcells,
            "fast_s_per_mcell": t_fast8 / mcells,
            "speedup": t_base8 / t_fast8,
            "baseline_gflops": 8 * flop / t_base8 / 1e9,
            "fast_gflops": 8 * flop / t_fast8 / 1e9,
            "fast_serial_s": t_serial8,
            "max_abs_diff": float((base8 - fast8).abs().max()),
        },
        "measured_rates": peaks,
        "fast_layers": layers,
        "peak_rss_mb": peak_rss_mb(),
    }
    for k in ("one_pass", "symmetrised"):
        r = res[k]
        print(
            f"{k:12s} baseline {r['baseline_s']:.2f} s ({r['baseline_s_per_mcell']:.2f} s/Mcell, "
            f"{r['baseline_gflops']:.1f} GFLOP/s)  fast {r['fast_s']:.2f} s ({r['fast_s_per_mcell']:.2f} s/Mcell, "
            f"{r['fast_gflops']:.1f} GFLOP/s)  {r['speedup']:.2f}x  max |diff| {r['max_abs_diff']:.1e}"
        )
    print(
        f"symmetrised, the 8 passes one after another on all threads: {t_serial8:.2f} s "
        f"(side by side, one thread each: {t_fast8:.2f} s, {t_serial8 / t_fast8:.2f}x)"
    )
    print(
        f"measured rates: plain 256->256 3x3 conv {peaks['plain_conv_256x256_3x3_gflops']:.1f} GFLOP/s, "
        f"24->24 3x3 conv+ReLU {peaks['conv_24x24_3x3_relu_gflops']:.1f} GFLOP/s; fast one pass at "
        f"{res['one_pass']['fast_gflops'] / peaks['plain_conv_256x256_3x3_gflops']:.0%} of the plain conv's"
    )
    for row in layers:
        print(f"  {row['layer']:22s} {row['s']:.3f} s  {row['gflops']:.1f} GFLOP/s")
    print(f"load after: {os.getloadavg()[0]:.2f}")
    write_json("bench_guide", res)
    return res


if __name__ == "__main__":
    main()
