r"""The amortised guide against patch Gibbs with the same prior and against p21 OGM, on held-out 2D maps.

Held-out simulated maps, never trained on: (A) maps drawn from the guide's prior (``patch3:generated``) given
the pose cells are free, from a seed stream the training never used; (B) windows of ``mapgen`` maps of
held-out seeds (the corpus the prior's tables were counted on used seed 0), poses in their free cells. Readings
come from the forward model (``GaussianRange(sigma)``, ``beams``-beam 360 degree scans, ``range_cells`` cells),
as in training (:func:`~ogm_ppl.inference.variational.amortised.random_scene`).

For every map (:func:`evaluate`): the guide's one-pass marginals, 3 x 3 patch Gibbs (the tile prior's sampler,
thesis Section 5.2.2) run long from two chains as the reference posterior marginals ``r``, and p21 OGM (Section
2.5, unknown = 0.5), scored against the true map over the latent cells (best F1, ROC AUC, NLL in bits per cell,
ECE) with their wall times. Then, for ``C`` chains of each sampler (3 x 3 patch Gibbs from
the default start (thresholded Hähnel OGM), from the guide's mean-field mode, from the guide's tile mode (each
tile's most likely configuration under its table tilted by the guide), and Gibbs mixed (``p_guide``) with guide
block proposals (:class:`~ogm_ppl.inference.mcmc.guided.GuidedGibbs`: blocks of tilted tile tables, and 3 x 3
windows of the guide's independent Bernoullis)), at each sweep ``t``:

* the running distance ``d_t = mean_k |mean_{c, s <= t} m^{(c,s)}_k - r_k|`` of the pooled running marginals,
  and the sweeps until it stays within each of :data:`THRESHOLDS` (:func:`sweeps_to`);
* the ensemble excess ``mean_k |mean_c m^{(c,t)}_k - r_k| - E|Binomial(C, r_k) / C - r_k|`` over what ``C``
  exact independent draws give;
* the log-joint gap: the chains' median ``log p(m, z)`` minus the stationary median of the reference chains.

Last, the acceptance rate of guide moves by block size, from a state of the reference chain.
:func:`summarise` averages per set (and over all maps); :func:`markdown` writes the tables.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from scipy.stats import binom

from ogm_ppl import GaussianRange
from ogm_ppl.datasets.mapgen import KINDS, generate_map
from ogm_ppl.inference.log_odds import evidence_grid
from ogm_ppl.inference.mcmc import PatchGibbs
from ogm_ppl.inference.mcmc.guided import GuidedGibbs
from ogm_ppl.inference.variational.amortised import SHIPPED_GUIDE, AmortisedGuide, guide_initial_map, random_scene
from ogm_ppl.metrics import best_f1, expected_calibration_error, nll_bits, roc_auc
from ogm_ppl.models.delta import delta_by_name
from ogm_ppl.priors.named import prior_by_name

__all__ = [
    "THRESHOLDS",
    "GuideEvalResult",
    "GuideEvalSettings",
    "evaluate",
    "guide_eval",
    "make_maps",
    "markdown",
    "run_chain",
    "scores",
    "summarise",
    "sweeps_to",
]

#: the distances ``d`` of the running marginals to the reference that :func:`sweeps_to` counts sweeps to
THRESHOLDS = (0.05, 0.03, 0.02)


class GuideEvalSettingsError(ValueError):
    """A setting of :class:`GuideEvalSettings` out of range; ``option`` names it, the message the limit."""

    def __init__(self, option: str, reason: str) -> None:
        super().__init__(f"{option}: {reason}")
        self.option, self.reason = option, reason


@dataclass(frozen=True)
class GuideEvalSettings:
    """The evaluation's settings: the guide file ``guide`` (default the shipped one) and the prior ``prior`` it
    was trained for; ``maps_a`` maps drawn from the prior and ``maps_b`` mapgen windows, ``size x size`` cells,
    each scanned from ``poses`` poses with ``beams`` beams of range ``range_cells`` cells and noise ``sigma``
    cells; the reference: 2 chains of ``ref_warmup + ref_sweeps`` sweeps; ``chains`` chains of ``sweeps`` sweeps
    per sampler; guided Gibbs with ``block`` blocks and guide moves with probability ``p_guide``;
    ``acc_passes`` passes per block size for the acceptance rates; ``seed`` of the held-out maps.

    Raises :class:`GuideEvalSettingsError` naming the first setting out of range."""

    guide: str = str(SHIPPED_GUIDE)
    prior: str = "patch3:generated"
    maps_a: int = 6
    maps_b: int = 4
    size: int = 32
    poses: int = 3
    beams: int = 120
    range_cells: float = 12.0
    sigma: float = 1.0
    ref_warmup: int = 200
    ref_sweeps: int = 1500
    chains: int = 10
    sweeps: int = 60
    block: tuple[int, int] = (6, 6)
    p_guide: float = 0.5
    acc_passes: int = 3
    seed: int = 2024

    def __post_init__(self) -> None:
        object.__setattr__(self, "guide", str(self.guide))
        object.__setattr__(self, "block", tuple(int(b) for b in self.block))
        for f in ("maps_a", "maps_b", "ref_warmup", "acc_passes", "seed"):
            if getattr(self, f) < 0:
                raise GuideEvalSettingsError(f, f"must be at least 0, got {getattr(self, f)}")
        for f in ("poses", "beams", "ref_sweeps", "chains", "sweeps"):
            if getattr(self, f) < 1:
                raise GuideEvalSettingsError(f, f"must be at least 1, got {getattr(self, f)}")
        if self.maps_a + self.maps_b < 1:
            raise GuideEvalSettingsError("maps_a", "maps_a + maps_b must be at least 1")
        if not 3 <= self.size <= 95:  # set B's windows lie inside a 120 x 120 map with a 12-cell margin
            raise GuideEvalSettingsError("size", f"must be between 3 and 95 cells, got {self.size}")
        if len(self.block) != 2 or min(self.block) < 1:
            raise GuideEvalSettingsError("block", f"must be two sides of at least 1 cell, got {self.block}")
        if not (self.range_cells > 0 and self.sigma > 0):
            raise GuideEvalSettingsError("range_cells" if self.range_cells <= 0 else "sigma", "must be positive")
        if not 0.0 <= self.p_guide <= 1.0:
            raise GuideEvalSettingsError("p_guide", f"must be between 0 and 1, got {self.p_guide}")


def scores(q: torch.Tensor | np.ndarray, truth: np.ndarray, mask: np.ndarray) -> dict:
    """Marginals ``q`` (``(K,)``) scored against the true map ``truth`` on the cells ``mask`` (``(K,)`` bool):
    ``{"best_f1", "auc", "nll_bits", "ece"}`` (:mod:`ogm_ppl.metrics`)."""
    q = q.numpy() if isinstance(q, torch.Tensor) else q
    t = truth.ravel().astype(bool)
    return {
        "best_f1": best_f1(q, t, mask=mask)[0],
        "auc": roc_auc(q, t, mask=mask),
        "nll_bits": nll_bits(q, t, mask=mask),
        "ece": expected_calibration_error(q, t, mask=mask),
    }


def make_maps(settings: GuideEvalSettings) -> list[dict]:
    """The held-out maps: ``{"set": "A:prior" | "B:mapgen", "name", "truth": (size, size) array, "model":
    OccupancyModel with the simulated readings}`` for the ``maps_a`` maps of set A, then the ``maps_b`` of set
    B (a ``SeedSequence(seed)`` child stream each)."""
    out = []
    shape = (settings.size, settings.size)
    prior = prior_by_name(settings.prior, shape)
    sensor = GaussianRange(settings.sigma)
    ss_a, ss_b = np.random.SeedSequence(settings.seed).spawn(2)
    rng = np.random.default_rng(ss_a)
    for i in range(settings.maps_a):
        scene = random_scene(prior, shape, settings.poses, settings.beams, settings.range_cells, sensor, rng)
        m0 = scene.model()
        gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
        truth = m0.prior.sample_given_free(m0.known_free, (), generator=gen)
        z = m0.simulate_readings(truth, generator=gen)
        out.append(
            {"set": "A:prior", "name": f"prior_{i}", "truth": truth.numpy().reshape(shape), "model": scene.model(z)}
        )
    rng = np.random.default_rng(ss_b)
    for i in range(settings.maps_b):
        kind = KINDS[i % len(KINDS)]
        big = generate_map(kind, (120, 120), np.random.default_rng(rng.integers(2**62)), border=20)
        for _ in range(100):  # a window with some wall and some free space
            r0, c0 = rng.integers(12, 120 - 12 - settings.size, 2)
            win = big[r0 : r0 + settings.size, c0 : c0 + settings.size]
            if 0.1 < win.mean() < 0.6:
                break
        scene = random_scene(prior, shape, settings.poses, settings.beams, settings.range_cells, sensor, rng, free=~win)
        m0 = scene.model()
        truth = torch.from_numpy(win.ravel().astype(np.float64))
        gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
        z = m0.simulate_readings(truth, generator=gen)
        out.append({"set": "B:mapgen", "name": f"{kind}_{i}", "truth": win.copy(), "model": scene.model(z)})
    return out


def run_chain(kernel: Any, sweeps: int, seed: int, latent: np.ndarray) -> tuple[np.ndarray, float]:
    """Per-sweep states of one chain of ``kernel`` from torch seed ``seed`` (``sweeps x L`` uint8 over the
    ``L`` latent cells ``latent``) and its seconds (set-up included)."""
    torch.manual_seed(seed)
    t0 = time.perf_counter()
    kernel.setup()
    params = kernel.initial_params
    out = np.empty((sweeps, len(latent)), np.uint8)
    for t in range(sweeps):
        params = kernel.sample(params)
        v = params["m"]
        out[t] = (v.numpy() if v.shape[-1] == len(latent) else v.numpy()[latent]).astype(np.uint8)
    return out, time.perf_counter() - t0


def _full(model, latent_states: np.ndarray) -> torch.Tensor:
    maps = torch.zeros(len(latent_states), model.num_cells, dtype=torch.float64)
    maps[:, model.latent] = torch.from_numpy(latent_states.astype(np.float64))
    return maps


def sweeps_to(dist: np.ndarray, d: float) -> int | None:
    """The first sweep (1-based) from which ``dist`` (one value per sweep) stays at most ``d``, or ``None``
    when it does not within the horizon.

    >>> sweeps_to(np.array([0.5, 0.1, 0.3, 0.01, 0.02]), 0.05), sweeps_to(np.array([0.5, 0.1]), 0.05)
    (4, None)
    """
    above = np.flatnonzero(dist > d)
    if len(above) == 0:
        return 1
    t = int(above[-1]) + 2
    return t if t <= len(dist) else None


def evaluate(item: dict, guide: AmortisedGuide, settings: GuideEvalSettings) -> dict:
    """One held-out map of :func:`make_maps` evaluated (module docstring): ``{"set", "name", "cells",
    "occupied_share", "ref_chain_gap", "methods": {"guide", "gibbs_long", "p21_ogm"}: scores and seconds,
    "guide_vs_ref_mean_abs", "p21_vs_ref_mean_abs", "ref_log_joint", "ensemble_noise_floor", "convergence":
    {sampler: per-sweep curves and sweeps to each threshold}, "acceptance_by_block"}``."""
    model, truth = item["model"], item["truth"]
    latent = model.latent.numpy()
    mask = np.zeros(model.num_cells, bool)
    mask[latent] = True
    res = {
        "set": item["set"],
        "name": item["name"],
        "cells": int(mask.sum()),
        "occupied_share": float(truth.ravel()[mask].mean()),
    }
    # (a) the guide, one pass
    t0 = time.perf_counter()
    q_guide = guide.marginals(model)
    t_guide = time.perf_counter() - t0
    t0 = time.perf_counter()
    q_p21 = evidence_grid(model.rays, delta_by_name("p21")).probabilities
    t_p21 = time.perf_counter() - t0
    # the reference: long 3 x 3 patch Gibbs, two chains
    refs, t_ref, kept = [], 0.0, []
    for c in range(2):
        states, sec = run_chain(PatchGibbs(model, (3, 3)), settings.ref_warmup + settings.ref_sweeps, 1000 + c, latent)
        refs.append(states[settings.ref_warmup :].mean(0))
        kept.append(states[settings.ref_warmup :])
        t_ref += sec
    ref_states = np.concatenate(kept)
    ref = np.zeros(model.num_cells)
    ref[latent] = (refs[0] + refs[1]) / 2
    res["ref_chain_gap"] = float(np.abs(refs[0] - refs[1]).mean())
    res["methods"] = {
        "guide": {**scores(q_guide, truth, mask), "seconds": t_guide},
        "gibbs_long": {
            **scores(ref, truth, mask),
            "seconds": t_ref,
            "sweeps": 2 * (settings.ref_warmup + settings.ref_sweeps),
        },
        "p21_ogm": {**scores(q_p21, truth, mask), "seconds": t_p21},
    }
    res["guide_vs_ref_mean_abs"] = float(np.abs(q_guide.numpy()[latent] - ref[latent]).mean())
    res["p21_vs_ref_mean_abs"] = float(np.abs(q_p21.numpy()[latent] - ref[latent]).mean())
    # (b, c) sweeps to the long-run marginals
    tile_mode = model.full_map(
        GuidedGibbs(PatchGibbs(model, (3, 3)), guide, block=(3, 3), proposal="tiles").initial_params["m"]
    )
    variants = {
        "gibbs_default_init": lambda: PatchGibbs(model, (3, 3)),
        "gibbs_guide_init": lambda: PatchGibbs(model, (3, 3), init=guide_initial_map(guide, model)),
        "gibbs_guide_tile_init": lambda: PatchGibbs(model, (3, 3), init=tile_mode),
        "guided_tiles": lambda: GuidedGibbs(
            PatchGibbs(model, (3, 3)),
            guide,
            block=tuple(settings.block),
            p_guide=settings.p_guide,
            init="guide",
            proposal="tiles",
        ),
        "guided_bernoulli": lambda: GuidedGibbs(
            PatchGibbs(model, (3, 3)), guide, block=(3, 3), p_guide=settings.p_guide, init="guide"
        ),
    }
    ref_l = ref[latent]
    C = settings.chains
    # E|Binomial(C, p)/C - p| per cell: the distance C exact independent draws have from p
    j = np.arange(C + 1)
    floor = float((binom.pmf(j[None, :], C, ref_l[:, None]) * np.abs(j[None, :] / C - ref_l[:, None])).sum(1).mean())
    lj_ref = model.log_joint(_full(model, ref_states[:: max(1, len(ref_states) // 400)]))
    lj_ref = lj_ref[torch.isfinite(lj_ref)]
    res["ref_log_joint"] = {"mean": float(lj_ref.mean()), "median": float(lj_ref.median()), "sd": float(lj_ref.std())}
    res["ensemble_noise_floor"] = floor
    conv: dict[str, dict] = {}
    for name, make in variants.items():
        chains: list[np.ndarray] = []
        secs, rates = 0.0, []
        for c in range(C):
            k = make()
            states, sec = run_chain(k, settings.sweeps, 2000 + c, latent)
            chains.append(states)
            secs += sec
            if isinstance(k, GuidedGibbs):
                rates.append(k.acceptance_rate)
        runs = np.stack(chains)  # C x T x L
        total = runs.sum(0)
        running = np.cumsum(total, 0) / (np.arange(1, settings.sweeps + 1)[:, None] * C)
        dist = np.abs(running - ref_l).mean(1)
        excess = np.abs(total / C - ref_l).mean(1) - floor
        lj = model.log_joint(_full(model, runs.reshape(-1, len(latent)))).reshape(C, settings.sweeps)
        gap = (lj.median(0).values - res["ref_log_joint"]["median"]).numpy()  # medians: a chain may sit at -inf
        se = 1.25 * res["ref_log_joint"]["sd"] / np.sqrt(C)  # of a median of C draws
        conv[name] = {
            "seconds_per_sweep": secs / (C * settings.sweeps),
            "running_dist": dist.tolist(),
            "ensemble_excess": excess.tolist(),
            "log_joint_gap": gap.tolist(),
            "chains_at_zero_mass": (~torch.isfinite(lj)).sum(0).tolist(),
            "sweeps_to": {str(d): sweeps_to(dist, d) for d in THRESHOLDS},
            "sweeps_to_excess_0.01": sweeps_to(excess, 0.01),
            "sweeps_to_log_joint_2se": sweeps_to(np.abs(gap), 2 * se),
        }
        if rates:
            conv[name]["guide_acceptance"] = float(np.mean(rates))
    res["convergence"] = conv
    # acceptance of guide moves by block size, from a state of the reference chain (near stationarity)
    start = _full(model, ref_states[-1:])[0]
    acc = {}
    for prop, blocks in (("bernoulli", [(1, 1), (3, 3), (6, 6)]), ("tiles", [(3, 3), (6, 6), (9, 9)])):
        for b in blocks:
            k = GuidedGibbs(PatchGibbs(model, (3, 3)), guide, block=b, p_guide=1.0, proposal=prop, init="base")
            torch.manual_seed(7)
            k.initial_params = {"m": start[model.latent]}
            k.setup()
            for _ in range(settings.acc_passes):
                k.mh_pass()
            acc[f"{prop}_{b[0]}x{b[1]}"] = k.acceptance_rate
    res["acceptance_by_block"] = acc
    return res


def summarise(results: list[dict], settings: GuideEvalSettings) -> dict:
    """Per set of maps (and ``"all"``) the means (medians for sweep counts and log-joint gaps) of
    :func:`evaluate`'s results: ``{set: {"maps", "scores", "convergence", "acceptance_by_block", ...}}``."""
    summary = {}
    for s in sorted({r["set"] for r in results}) + ["all"]:
        rows = [r for r in results if s in ("all", r["set"])]
        table = {}
        for meth in ("guide", "gibbs_long", "p21_ogm"):
            table[meth] = {
                k: float(np.mean([r["methods"][meth][k] for r in rows]))
                for k in ("best_f1", "auc", "nll_bits", "ece", "seconds")
            }
        conv = {}
        for v in rows[0]["convergence"]:
            c: dict[str, float | str] = {}
            for d in THRESHOLDS:
                vals = [r["convergence"][v]["sweeps_to"][str(d)] for r in rows]
                reached = [x for x in vals if x is not None]
                c[f"sweeps_to_{d}_median"] = float(np.median([x if x is not None else np.inf for x in vals]))
                c[f"reached_{d}"] = f"{len(reached)}/{len(vals)}"
            for key in ("sweeps_to_excess_0.01", "sweeps_to_log_joint_2se"):
                vals = [r["convergence"][v][key] for r in rows]
                c[f"{key}_median"] = float(np.median([x if x is not None else np.inf for x in vals]))
                c[f"{key}_reached"] = f"{sum(x is not None for x in vals)}/{len(vals)}"
            for t in (1, 2, 5, 10):
                t = min(t, settings.sweeps)
                c[f"log_joint_gap_at_{t}"] = float(
                    np.median([r["convergence"][v]["log_joint_gap"][t - 1] for r in rows])
                )
                c[f"excess_at_{t}"] = float(np.mean([r["convergence"][v]["ensemble_excess"][t - 1] for r in rows]))
            spw = float(np.mean([r["convergence"][v]["seconds_per_sweep"] for r in rows]))
            c["seconds_per_sweep"] = spw
            for t in sorted({min(t, settings.sweeps) for t in (1, 10, 50)} | {settings.sweeps}):
                c[f"running_dist_at_{t}"] = float(np.mean([r["convergence"][v]["running_dist"][t - 1] for r in rows]))
            if "guide_acceptance" in rows[0]["convergence"][v]:
                c["guide_acceptance"] = float(np.mean([r["convergence"][v]["guide_acceptance"] for r in rows]))
            conv[v] = c
        acc = {k: float(np.mean([r["acceptance_by_block"][k] for r in rows])) for k in rows[0]["acceptance_by_block"]}
        summary[s] = {
            "maps": len(rows),
            "scores": table,
            "convergence": conv,
            "acceptance_by_block": acc,
            "guide_vs_ref_mean_abs": float(np.mean([r["guide_vs_ref_mean_abs"] for r in rows])),
            "p21_vs_ref_mean_abs": float(np.mean([r["p21_vs_ref_mean_abs"] for r in rows])),
            "ref_chain_gap": float(np.mean([r["ref_chain_gap"] for r in rows])),
            "speedup_guide_vs_gibbs_long": table["gibbs_long"]["seconds"] / table["guide"]["seconds"],
        }
    return summary


def markdown(summary: dict, settings: GuideEvalSettings, meta: dict) -> str:
    """The tables of :func:`summarise`'s ``summary`` as Markdown (``meta``: what the guide was trained for)."""
    cfg = settings
    lines = [
        "# Amortised guide vs Gibbs with the same prior vs p21 OGM",
        "",
        f"Guide: `{cfg.guide}` (trained for {meta}). Prior `{cfg.prior}`; maps {cfg.size} x {cfg.size}, "
        f"{cfg.poses} poses x {cfg.beams} beams, range {cfg.range_cells} cells, GaussianRange({cfg.sigma}). "
        f"Reference: 3 x 3 patch Gibbs, 2 chains x ({cfg.ref_warmup} warm-up + {cfg.ref_sweeps}) sweeps. "
        f"Scores over the latent cells against the true map; wall times on this machine (1 thread). "
        "Chain c of every sampler uses the same seed (common random numbers), so the samplers' differences "
        "are paired; once chains from different starts coalesce they make the same moves.",
        "",
    ]
    for s, v in summary.items():
        lines += [
            f"## Set {s} ({v['maps']} maps)",
            "",
            "| method | best F1 | AUC | NLL bits/cell | ECE | seconds |",
            "|---|---|---|---|---|---|",
        ]
        for meth, t in v["scores"].items():
            lines.append(
                f"| {meth} | {t['best_f1']:.3f} | {t['auc']:.3f} | {t['nll_bits']:.3f} | {t['ece']:.3f} | "
                f"{t['seconds']:.3g} |"
            )
        lines += [
            "",
            f"Speed-up of the guide over the long Gibbs run: {v['speedup_guide_vs_gibbs_long']:.0f}x. "
            f"Mean |marginal - reference|: guide {v['guide_vs_ref_mean_abs']:.4f}, p21 {v['p21_vs_ref_mean_abs']:.4f}; "
            f"the two reference chains differ by {v['ref_chain_gap']:.4f}.",
            "",
            f"Sweeps until the pooled running marginals of {cfg.chains} chains stay within mean |diff| <= d of the "
            "reference (median over maps; reached / maps):",
            "",
            "| sampler | " + " | ".join(f"d={d}" for d in THRESHOLDS) + " | dist@1 | dist@10 | dist@50 | "
            f"dist@{settings.sweeps} | s/sweep | guide accept |",
            "|---|" + "---|" * (len(THRESHOLDS) + 6),
        ]
        for name, c in v["convergence"].items():
            cells = [f"{c[f'sweeps_to_{d}_median']:.0f} ({c[f'reached_{d}']})" for d in THRESHOLDS]
            acc = f"{c['guide_acceptance']:.3f}" if "guide_acceptance" in c else "-"
            at = [c.get(f"running_dist_at_{min(t, settings.sweeps)}") for t in (1, 10, 50, settings.sweeps)]
            lines.append(
                f"| {name} | " + " | ".join(cells) + " | " + " | ".join(f"{x:.4f}" for x in at) + " | "
                f"{c['seconds_per_sweep'] * 1e3:.2f} ms | {acc} |"
            )
        lines += [
            "",
            f"Burn-in, from {settings.chains} independent chains at each sweep: the chains' median log joint minus "
            "the stationary median (nats; median over maps), and the excess of the chains' ensemble marginals over "
            "the distance "
            f"{settings.chains} exact draws would have (mean |diff| - its binomial expectation):",
            "",
            "| sampler | lj gap@1 | @2 | @5 | @10 | sweeps to |gap| < 2 se | excess@1 | @2 | @5 | @10 | sweeps to "
            "excess < 0.01 |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for name, c in v["convergence"].items():
            g = [c[f"log_joint_gap_at_{min(t, settings.sweeps)}"] for t in (1, 2, 5, 10)]
            e = [c[f"excess_at_{min(t, settings.sweeps)}"] for t in (1, 2, 5, 10)]
            lines.append(
                f"| {name} | "
                + " | ".join(f"{x:.1f}" for x in g)
                + f" | {c['sweeps_to_log_joint_2se_median']:.0f} ({c['sweeps_to_log_joint_2se_reached']}) | "
                + " | ".join(f"{x:.4f}" for x in e)
                + f" | {c['sweeps_to_excess_0.01_median']:.0f} ({c['sweeps_to_excess_0.01_reached']}) |"
            )
        lines += [
            "",
            f"Acceptance of guide moves by block ({settings.acc_passes} passes from a reference-chain state): "
            + ", ".join(f"{k} {a:.3f}" for k, a in v["acceptance_by_block"].items()),
            "",
        ]
    return "\n".join(lines) + "\n"


@dataclass
class GuideEvalResult:
    """An evaluation: the ``per_map`` results of :func:`evaluate`, their ``summary`` (:func:`summarise`), what
    the guide was ``trained_for`` and the ``seconds`` it took."""

    per_map: list[dict]
    summary: dict
    trained_for: dict
    seconds: float


def guide_eval(
    settings: GuideEvalSettings | None = None,
    *,
    guide: AmortisedGuide | None = None,
    progress: bool = True,
) -> GuideEvalResult:
    """Evaluate the guide ``settings.guide`` (or ``guide``, already loaded) on the held-out maps of
    :func:`make_maps` (module docstring); writes nothing. ``progress``: a progress line over the maps."""
    from ogm_ppl.progress import Progress

    s = settings or GuideEvalSettings()
    guide = AmortisedGuide.load(s.guide) if guide is None else guide
    t0 = time.perf_counter()
    items = make_maps(s)
    results = []
    with Progress(len(items), "maps", unit="map", enabled=progress, every=5.0) as bar:
        for it in items:
            results.append(evaluate(it, guide, s))
            bar.update(note=it["name"])
    return GuideEvalResult(results, summarise(results, s), guide.trained_for, time.perf_counter() - t0)
