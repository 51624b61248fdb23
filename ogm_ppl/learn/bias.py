r"""Prior biases: the ``h`` of :class:`~ogm_ppl.priors.BiasedPrior` that makes a prior fill an empty window as
its training corpus is filled (``ogm-ppl calibrate --bias-file``, :func:`~ogm_ppl.calibration.load_bias_file`).

Far from any reading a prior predicts what it holds itself: ``E_p[mean_k m_k]``, the occupied share of its own
draws. The tables of Chapter 5 (thesis Sections 5.2.2-5.2.3) are products of tile conditionals, not normalised
fits of a joint, so that share need not be the corpus's ``lambda``. Among the priors
``p~(m) exp(h sum_k m_k)`` the bias ``h`` solves the moment condition

.. math::

    s(h) = E_{p_h}\Big[\frac{1}{|K|} \sum_{k \in K} m_k\Big] = \lambda,

``K`` the cells of a ``window x window`` square with no readings (one short ray at its centre, which the
model needs; its cells are not counted). ``s(h)`` rises with ``h`` and is estimated by chains of the prior's
mixing cycle (:func:`~ogm_ppl.inference.mcmc.mixing_cycle`, the calibration protocol's ``cycle`` sampler),
each recording the share every ``every`` sweeps and averaged over the second half of the record
(:func:`occupancy_trace`). ``h`` is found by ``bias_steps`` bisection steps on ``[-R, R]`` (``bias_range``) of
the share of two chains (all-free and all-occupied starts); the three-chain trace (adding a prior draw's
start) at the chosen ``h`` is recorded. ``lambda`` is the occupied share of the corpus's shipped tables (the
learned independent prior's): only training plans enter.

:func:`fit_bias` writes ``bias.json`` (``{"format": "ogm_ppl.prior_bias", "bias": {prior name: h}, ...}`` with
each fit's bisection, shares and provenance) into the folder named (``ogm-ppl fit-prior bias --priors KIND ...
--train CORPUS ... --out DIR``).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ogm_ppl.learn._fit_common import (
    CORPORA,
    SHIPPED_CORPORA,
    FitOptionError,
    FitResult,
    check_float,
    check_int,
    check_out_dir,
)
from ogm_ppl.learn._heldout import shell_command

__all__ = ["PRIORS", "STARTS", "BiasSettings", "bias_by_bisection", "empty_model", "fit_bias", "occupancy_trace"]

#: the kinds whose bias is fitted by default
PRIORS: tuple[str, ...] = ("border_bo", "border_bo@cal", "border1_bo", "border1_bo@cal", "patch3")
#: the chains' starts: the all-free map, the all-occupied map, a prior draw
STARTS: tuple[str, ...] = ("free", "occupied", "prior")
#: the file written
FILE_NAME = "bias.json"


@dataclass(frozen=True)
class BiasSettings:
    """The settings of the chains: a ``window`` x ``window`` square, ``sweeps`` sweeps a chain, the share
    recorded every ``every`` sweeps, ``seed`` (chain ``j`` is seeded ``seed + 1000 j``), and the bisection:
    ``bias_steps`` steps on ``[-bias_range, bias_range]``."""

    window: int = 96
    sweeps: int = 1000
    every: int = 50
    seed: int = 0
    bias_range: float = 2.0
    bias_steps: int = 7

    def checked(self) -> BiasSettings:
        """These settings, each checked (:class:`~ogm_ppl.learn.FitOptionError` names the first out of range)."""
        check_int(self.window, "window", 4, 4096)
        every = check_int(self.every, "every", 1)
        check_int(self.sweeps, "sweeps", 2 * every, 10_000_000)
        check_int(self.seed, "seed", 0, 2**31 - 1)
        check_float(self.bias_range, "bias_range", 0.0, 100.0)
        check_int(self.bias_steps, "bias_steps", 1, 60)
        return self

    def options(self) -> list[str]:
        """The command-line options that differ from the defaults."""
        d = BiasSettings()
        return [
            a
            for k, v in asdict(self).items()
            if v != getattr(d, k)
            for a in ("--" + k.replace("_", "-"), f"{v:g}" if isinstance(v, float) else str(v))
        ]


def empty_model(prior: Any, window: int) -> tuple[Any, np.ndarray]:
    """A ``window x window`` model whose only reading is one short ray at the centre, and the cells it does not
    touch (the ones counted)."""
    from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast

    grid = Grid((window, window), resolution=1.0)
    c = window / 2 + 0.5
    scans = Scans(np.array([[c, c, 0.0]]), np.array([0.0]), np.array([[0.5]]), max_range=float(window))
    rays = raycast(grid, scans)
    counted = ~rays.reached()
    return OccupancyModel(grid, rays, GaussianRange(1.0), prior), counted


def occupancy_trace(name: str, settings: BiasSettings, bias: float = 0.0, starts: Sequence[str] = STARTS) -> dict:
    """Chains under the prior ``name`` (times ``exp(bias sum_k m_k)``) on an empty window, one from each of
    ``starts``: ``{"traces": the share every settings.every sweeps, "share": the mean over the second halves,
    "chain_shares", "seconds", "patch"}``."""
    import torch

    from ogm_ppl.calibration import default_patch
    from ogm_ppl.inference.mcmc import mixing_cycle
    from ogm_ppl.priors import BiasedPrior
    from ogm_ppl.priors.named import prior_by_name

    prior = prior_by_name(name, (settings.window, settings.window))
    patch = default_patch(prior)
    if bias:
        prior = BiasedPrior(prior, bias)
    model, counted = empty_model(prior, settings.window)
    traces, secs = [], []
    for j, start in enumerate(starts):
        init = torch.ones(model.num_cells, dtype=torch.float64) if start == "occupied" else start
        kernel = mixing_cycle(model, patch, init=init)
        torch.manual_seed(settings.seed + 1000 * j)
        kernel.setup()
        params = kernel.current_params()
        t0 = time.perf_counter()
        tr = []
        for i in range(settings.sweeps):
            params = kernel.sample(params)
            if (i + 1) % settings.every == 0:
                tr.append(float(kernel.state[counted].mean()))
        traces.append(tr)
        secs.append(time.perf_counter() - t0)
    half = np.array([t[len(t) // 2 :] for t in traces])
    return {
        "traces": traces,
        "share": float(half.mean()),
        "chain_shares": [float(v) for v in half.mean(1)],
        "seconds": float(sum(secs)),
        "patch": None if patch is None else list(patch),
    }


def bias_by_bisection(name: str, target: float, settings: BiasSettings, progress: bool = False) -> dict:
    """The bias ``h`` whose prior fills ``target`` of an empty window: ``settings.bias_steps`` bisection steps
    of the two-chain share (all-free, all-occupied starts) on ``[-R, R]``, then the three-chain trace at ``h``:
    ``{"bias", "steps": [[h, share], ...], **occupancy_trace(name, settings, h)}``; ``progress``: a line a step."""
    lo, hi = -settings.bias_range, settings.bias_range
    steps = []
    for _ in range(settings.bias_steps):
        h = 0.5 * (lo + hi)
        share = occupancy_trace(name, settings, h, starts=("free", "occupied"))["share"]
        steps.append([h, share])
        if progress:
            print(f"  {name} step {len(steps)}/{settings.bias_steps}: h {h:+.4f} -> share {share:.3f}", flush=True)
        lo, hi = (h, hi) if share < target else (lo, h)
    h = 0.5 * (lo + hi)
    return {"bias": h, "steps": steps, **occupancy_trace(name, settings, h)}


def prior_targets(priors: Sequence[str], train: Sequence[str]) -> tuple[list[tuple[str, str, str]], dict[str, str]]:
    """``([(prior name, kind, corpus), ...], {skipped name: reason})`` of the kinds on the training corpora
    (``KIND:CORPUS[@MOD]``; a ``@cal`` kind without a fitted exponent on a corpus is skipped there), checked:
    :class:`FitOptionError` names ``priors`` or ``train``."""
    from ogm_ppl.calibration import prior_names
    from ogm_ppl.priors.named import load_temper_params, prior_kinds, split_prior_name

    if not priors or len(set(priors)) != len(priors):
        raise FitOptionError("priors", f"give one or more distinct prior kinds, got {list(priors)}")
    if not train or len(set(train)) != len(train) or any(c not in CORPORA for c in train):
        raise FitOptionError("train", f"give one or more distinct corpora of {', '.join(CORPORA)}, got {list(train)}")
    for k in priors:
        try:
            kind, corpus, _, _ = split_prior_name(k)
        except ValueError as e:
            raise FitOptionError("priors", str(e)) from None
        if corpus:
            raise FitOptionError("priors", f"takes kinds (the corpora are train), got {k!r}")
        if kind not in prior_kinds():
            raise FitOptionError("priors", f"{k!r} is not a prior kind; known: {', '.join(prior_kinds())}")
    out, skipped = [], {}
    for corpus in train:
        for kind in priors:
            base, _, _, mod = split_prior_name(kind)
            name = prior_names([kind], [corpus])[-1][0]  # KIND:CORPUS[@MOD]
            if mod == "cal" and base not in load_temper_params(corpus).beta:
                skipped[name] = "no tempering exponent fitted"
                continue
            out.append((name, kind, corpus))
    if not out:
        raise FitOptionError("priors", f"nothing to fit: {', '.join(f'{n} ({r})' for n, r in skipped.items())}")
    return out, skipped


def fit_bias(
    priors: Sequence[str],
    out_dir: str | os.PathLike,
    *,
    train: Sequence[str] = SHIPPED_CORPORA,
    settings: BiasSettings | None = None,
    progress: bool = True,
) -> FitResult:
    """Fit the bias ``h`` of each prior kind on each training corpus (module docstring) and write ``bias.json``
    into ``out_dir`` (nothing else, atomically).

    Args:
        priors: prior kinds, ``KIND`` or ``KIND@cal`` (the corpus comes from ``train``).
        out_dir: the folder the file goes to (created if missing).
        train: the corpora whose shipped priors are biased (target: their tables' ``lambda``).
        settings: :class:`BiasSettings` (the chains and the bisection).
        progress: a line per prior and bisection step.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit).
    """
    s = (settings or BiasSettings()).checked()
    out = check_out_dir(out_dir)
    targets, skipped = prior_targets(list(priors), list(train))
    cmd = shell_command("bias", "--priors", *priors, "--train", *train, "--out", out, *s.options())
    from ogm_ppl.io import atomic_write_text, writable_folder
    from ogm_ppl.priors.tables import tables_by_name
    from ogm_ppl.provenance import provenance

    writable_folder(out)
    t0 = time.perf_counter()
    fits: dict[str, dict] = {}
    for name, kind, corpus in targets:
        lam = float(tables_by_name(corpus).lam)
        f = bias_by_bisection(name, lam, s, progress)
        fits[name] = {"kind": kind, "train": corpus, "corpus_share": lam, **f}
        if progress:
            chains = " ".join(f"{v:.3f}" for v in f["chain_shares"])
            print(f"{name:28s} corpus {lam:.3f} -> h {f['bias']:+.3f}: share {f['share']:.3f} ({chains})", flush=True)
    for name, reason in skipped.items():
        if progress:
            print(f"{name:28s} skipped: {reason}", flush=True)
    seconds = round(time.perf_counter() - t0, 1)
    prov = {**provenance(cmd), "fitted_by": "ogm_ppl.learn.fit_bias", "seconds": seconds}
    doc = {
        "format": _format(),
        "provenance": prov,
        "settings": {"priors": list(priors), "train": list(train), **asdict(s)},
        "starts": list(STARTS),
        "bias": {n: f["bias"] for n, f in fits.items()},
        "skipped": skipped,
        "fits": fits,
    }
    path = atomic_write_text(out / FILE_NAME, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return FitResult("bias", (path,), prov, {"bias": doc["bias"], "skipped": skipped}, seconds)


def _format() -> str:
    from ogm_ppl.calibration import BIAS_FORMAT

    return BIAS_FORMAT
