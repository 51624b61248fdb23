r"""Net fields of a corpus or of plans of one's own: the workflow around :mod:`ogm_ppl.priors.learn_net`.

A net field (:class:`~ogm_ppl.priors.NetFieldPrior`) scores a map by a small network on every ``w x w`` window,
``log p~(m) = a sum_k m_k + sum_windows sum_h v_h sum_{g in D4} sigma(<g W_h, x> + b_h)``. The fit:

1. ``pl_steps`` Adam steps of maximum pseudo-likelihood, ``min 1/N sum_k -log p(m_k | m_-k) + lambda_/2 |theta|^2``,
   each on ``pl_batch`` cells drawn uniformly from the training plans' cells whose ``(2w - 1)^2`` neighbourhood is
   known (exact conditionals, :func:`~ogm_ppl.priors.learn_net.pl_loss`), the step size decaying from ``pl_lr`` to
   ``pl_lr / 20`` on a half cosine (:func:`pl_step_size`);
2. ``pcd_steps`` Adam steps of persistent contrastive divergence from there: ``pcd_chains`` chains of
   ``pcd_size x pcd_size`` cells, started from crops of the training plans and carried between steps, each step
   moved by ``pcd_sweeps`` compiled Gibbs sweeps of the current field
   (:func:`~ogm_ppl.priors.learn_net.pcd_loss`), against as many fresh crops of the training plans.

**Stopping point.** Every ``eval_every`` steps (and at the end of each stage) the held-out score is the mean
``-log p(m_k | m_-k)`` of the validation plans' cells whose neighbourhood is known, by the compiled conditionals in
float64 (:func:`~ogm_ppl.priors.learn_net.heldout_nll`); the parameters of the best score are written, with the
training plans' occupied share as the field's ``occupancy`` (what the model reads past the grid's edge: a field in
its ordered phase freezes prior chains, which then say nothing of its marginal).

The plans are split in their order: every ``validation_every``-th plan (10 by default) is validation, the rest
train. :func:`fit_net_field` writes ``net_<name>.npz`` (read by :func:`~ogm_ppl.priors.net_field.net_from_file`)
and ``net_<name>.json`` (settings, provenance, the score curve, a sampler check). After every evaluation the state
(parameters, the optimiser's moments, the chains, the curve) goes to ``net_<name>.checkpoint.npz`` in the output
folder, and a rerun with the same options resumes there; each step draws its batch from a generator seeded by
``(seed, step)``, so a resumed fit repeats the steps an uninterrupted one takes. The checkpoint is removed when the
files are written.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shlex
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl.learn._fit_common import (
    FitOptionError,
    FitResult,
    PlanPaths,
    TrainingPlans,
    check_float,
    check_int,
    command,
    fit_setup,
    run_provenance,
)

__all__ = ["NetFieldSettings", "fit_net_field"]

VALIDATION_EVERY = 10
#: how the PCD chains start
PCD_INITS = ("data", "noise")
#: the stopping scores
SELECTS = ("pl", "unseen")
_PARAMS = ("filters", "bias", "out", "unary")


@dataclass(frozen=True)
class NetFieldSettings:
    """The settings of :func:`fit_net_field`. ``w``: window side; ``hidden``: filters, each in its 8 orientations
    (``8 hidden`` units); ``activation``: ``relu`` or ``softplus``; ``pad``: the value of a cell past the grid's
    edge; ``lambda_``: L2 penalty; ``pl_steps``/``pl_batch``/``pl_lr``: the pseudo-likelihood stage;
    ``pcd_steps``/``pcd_chains``/``pcd_size``/``pcd_sweeps``/``pcd_lr``: the PCD stage; ``eval_every``: steps between
    held-out scores (and checkpoints); ``check_size``/``check_sweeps``: the final sampler check; ``seed``;
    ``start``: a net-field file whose parameters start the fit (``pl_steps`` may then be 0); ``start_beta``: the
    PCD stage starts from the field raised to this power (output weights and unary bias times it); ``pcd_init``:
    the chains start from training crops (``data``) or uniform noise (``noise``); ``select``: the stopping score,
    held-out pseudo-likelihood (``pl``) or the unseen-cell NLL of :mod:`~ogm_ppl.learn._net_select` (``unseen``,
    on ``select_plans`` validation windows of ``select_window`` cells, ``select_sweeps`` sweeps a chain)."""

    w: int = 5
    hidden: int = 8
    activation: str = "relu"
    pad: float = 0.5
    lambda_: float = 1e-5
    pl_steps: int = 1500
    pl_batch: int = 2048
    pl_lr: float = 0.01
    pcd_steps: int = 100
    pcd_chains: int = 16
    pcd_size: int = 48
    pcd_sweeps: int = 2
    pcd_lr: float = 3e-4
    eval_every: int = 250
    check_size: int = 48
    check_sweeps: int = 100
    seed: int = 0
    start: str = ""
    start_beta: float = 1.0
    pcd_init: str = "data"
    select: str = "pl"
    select_plans: int = 3
    select_window: int = 64
    select_sweeps: int = 20

    def checked(self) -> NetFieldSettings:
        """These settings, each checked (:class:`~ogm_ppl.learn.FitOptionError` names the first out of range)."""
        from ogm_ppl.priors.compiled.net_field import ACTIVATIONS, MAX_NET_WINDOW, MAX_UNITS

        check_int(self.w, "w", 2, MAX_NET_WINDOW)
        check_int(self.hidden, "hidden", 1, MAX_UNITS // 8)
        if self.activation not in ACTIVATIONS:
            raise FitOptionError("activation", f"must be one of {', '.join(ACTIVATIONS)}, got {self.activation!r}")
        check_float(self.pad, "pad", 0.0, 1.0, lo_open=False)
        check_float(self.lambda_, "lambda_", 0.0, 1e3, lo_open=False)
        check_int(self.pl_steps, "pl_steps", 0 if self.start else 1, 10_000_000)
        check_int(self.pl_batch, "pl_batch", 1, 10_000_000)
        check_float(self.pl_lr, "pl_lr", 0.0, 10.0)
        check_int(self.pcd_steps, "pcd_steps", 0, 10_000_000)
        check_int(self.pcd_chains, "pcd_chains", 1, 4096)
        check_int(self.pcd_size, "pcd_size", 2 * self.w, 1024)
        check_int(self.pcd_sweeps, "pcd_sweeps", 1, 10_000)
        check_float(self.pcd_lr, "pcd_lr", 0.0, 10.0)
        check_int(self.eval_every, "eval_every", 1)
        check_int(self.check_size, "check_size", 17, 1024)
        check_int(self.check_sweeps, "check_sweeps", 1, 1_000_000)
        check_int(self.seed, "seed", 0, 2**32 - 1)
        check_float(self.start_beta, "start_beta", 0.0, 1.0)
        if self.pcd_init not in PCD_INITS:
            raise FitOptionError("pcd_init", f"must be one of {', '.join(PCD_INITS)}, got {self.pcd_init!r}")
        if self.select not in SELECTS:
            raise FitOptionError("select", f"must be one of {', '.join(SELECTS)}, got {self.select!r}")
        check_int(self.select_plans, "select_plans", 1, 100)
        check_int(self.select_window, "select_window", 16, 1024)
        check_int(self.select_sweeps, "select_sweeps", 1, 100_000)
        if self.start and not Path(self.start).is_file():
            raise FitOptionError("start", f"{self.start} is not a file (a net field of save_net_field)")
        return self

    def record(self) -> dict:
        """The settings as the fit's JSON records them, with the recipe in words."""
        d: dict[str, Any] = asdict(self)
        d["units"] = 8 * self.hidden
        d["pl"] = (
            "Adam on -mean log p(m_k | m_-k) over uniform batches of known-neighbourhood training cells, "
            "step size pl_lr falling to pl_lr / 20 on a half cosine"
        )
        chains = "training crops" if self.pcd_init == "data" else "uniform noise"
        d["pcd"] = f"Adam on (mean log p~(chains) - mean log p~(crops)) / cells; chains from {chains}, carried"
        d["stopping"] = (
            "the evaluated parameters of least held-out -log p(m_k | m_-k) on the validation plans"
            if self.select == "pl"
            else "the evaluated parameters of least unseen-cell NLL (bits) of 2 chains on sparse scans of "
            "validation windows (ogm_ppl.learn._net_select)"
        )
        if self.start:
            d["start_sha256"] = hashlib.sha256(Path(self.start).read_bytes()).hexdigest()
        return d

    def options(self) -> list[str]:
        """The command-line options that differ from the defaults."""
        d, opts = NetFieldSettings(), []
        for k, v in asdict(self).items():
            if v != getattr(d, k):
                opts += [f"--{k.replace('_', '-').rstrip('-')}", f"{v:g}" if isinstance(v, float) else str(v)]
        return opts


def fit_net_field(
    source: str | PlanPaths | TrainingPlans,
    out_dir: str | os.PathLike,
    *,
    settings: NetFieldSettings | None = None,
    limit: int | None = None,
    pixel_size: float | None = None,
    resolution: float = 0.05,
    name: str | None = None,
    validation_every: int = VALIDATION_EVERY,
    resume: bool = True,
    progress: bool = True,
) -> FitResult:
    """Fit a net field to ``source``'s training plans (module docstring) and write ``net_<name>.npz`` and
    ``net_<name>.json`` into ``out_dir`` (and, while it runs, a checkpoint there).

    Args:
        source, limit, pixel_size, resolution: the training plans, as :func:`~ogm_ppl.learn.fit_tables` takes them.
        out_dir: the folder the files go to (created if missing).
        settings: :class:`NetFieldSettings` (default: its defaults).
        name: the files' name part (default the corpus, or ``plans``).
        validation_every: every this-many-th plan is validation (at least 2, at most the number of plans).
        resume: continue from a checkpoint of the same fit in ``out_dir`` (``False``: start afresh).
        progress: print the stages' progress and scores.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit).
    """
    import torch

    from ogm_ppl.io import atomic_write_bytes, atomic_write_text
    from ogm_ppl.priors import learn_net as ln
    from ogm_ppl.priors.net_field import NET_FORMAT_VERSION, load_net_field, net_arrays, net_path
    from ogm_ppl.progress import Progress

    s = (settings or NetFieldSettings()).checked()
    out, plans, label, every, tr_idx, va_idx = fit_setup(
        source, out_dir, name, validation_every, limit=limit, pixel_size=pixel_size, resolution=resolution
    )
    opts = s.options() + ([] if every == VALIDATION_EVERY else ["--validation-every", str(every)])
    cmd = command("net-field", plans, out, opts + ([] if name is None else ["--name", name]))
    if out.resolve() == net_path(plans.corpus).parent.resolve() and not plans.files and name == plans.corpus:
        # the package's own folder: the command is --ship (no machine's path in a shipped record)
        cmd = shlex.join(["ogm-ppl", "fit-prior", "net-field", *plans.command_args(), *opts, "--ship"])
    say = print if progress else (lambda *a, **k: None)
    t0 = time.perf_counter()
    maps = [_pair(m) for m in plans.maps()]
    train, val = [maps[i] for i in tr_idx], [maps[i] for i in va_idx]
    cells = ln.CellBatches(train, s.w)
    if cells.n_cells == 0 or not any(len(ln.eligible_cells(k, s.w)) for _, k in val):
        raise FitOptionError(
            "plans", f"the training or validation plans hold no cell with a known {2 * s.w - 1}^2 area"
        )
    if not any(o.shape[0] >= s.pcd_size and o.shape[1] >= s.pcd_size for o, _ in train) and s.pcd_steps:
        raise FitOptionError("pcd_size", f"no training plan is {s.pcd_size} x {s.pcd_size} cells: use a smaller size")
    share = sum(float((o & k).sum()) for o, k in train) / max(sum(float(k.sum()) for _, k in train), 1.0)
    say(f"{label}: {len(train)} training / {len(val)} validation maps, {cells.n_cells:,} training cells", flush=True)

    key = hashlib.sha256(json.dumps([s.record(), plans.source, every], sort_keys=True).encode()).hexdigest()
    ckpt = out / f"net_{label}.checkpoint.npz"
    share = min(max(share, 1e-3), 1 - 1e-3)
    model = ln.NetModel(s.w, s.hidden, s.activation, s.pad, s.seed, unary=float(np.log(share / (1 - share))))
    if s.start:
        _load_start(model, s)
    sel = None
    if s.select == "unseen":
        from ogm_ppl.learn._net_select import selection_scenes

        val_names = [plans.names[i] for i in va_idx]
        sel = selection_scenes(val, val_names, s.select_plans, s.select_window, s.select_sweeps, seed=s.seed)
        if not sel.scenes:
            raise FitOptionError("select_window", f"no validation plan has a usable {s.select_window}-cell window")
        say(f"{label}: stopping score on {len(sel.scenes)} validation windows: {', '.join(sel.names)}", flush=True)
    total = s.pl_steps + s.pcd_steps
    state = _read_checkpoint(ckpt, key) if resume else None
    step, history = 0, []
    if s.pl_steps == 0 and state is None:
        _temper(model, s.start_beta)  # a started fit's PCD stage begins at once
    best: dict[str, Any] = {"nll": float("inf"), "step": 0, "params": model.arrays()}
    chains = np.zeros((s.pcd_chains, s.pcd_size**2), np.uint8)
    opt = torch.optim.Adam(model.parameters(), lr=s.pl_lr)
    if state is not None:
        step, history, best = state["step"], state["history"], state["best"]
        model.load_arrays(state["params"])
        chains = state["chains"]
        if step >= s.pl_steps:
            opt = torch.optim.Adam(model.parameters(), lr=s.pcd_lr)
        _load_adam(opt, state["adam"])
        say(f"{label}: resuming from {ckpt} at step {step} of {total}", flush=True)

    def evaluate(at: int, phase: str) -> None:
        nll, n = ln.heldout_nll(lambda shape: model.prior(shape).compiled(), val, s.w)
        row = {"step": at, "phase": phase, "heldout_nll": nll, "cells": n}
        if phase == "pcd":
            row["chain_occupancy"] = float(chains.mean())
        score = nll
        if sel is not None:
            from ogm_ppl.learn._net_select import unseen_nll

            score = row["unseen_nll_bits"] = unseen_nll(lambda shape: model.prior(shape, occupancy=share), sel)
        history.append(row)
        if score < best["nll"]:
            best.update(nll=score, step=at, params=model.arrays())
        more = "" if sel is None else f", unseen-cell NLL {score:.4f} bits"
        say(
            f"  step {at} ({phase}): held-out -log p(m_k | m_-k) = {nll:.5f} nats/cell over {n:,} cells{more}",
            flush=True,
        )
        state = {"key": key, "step": at, "history": history, "best": best, "params": model.arrays(), "chains": chains}
        _write_checkpoint(ckpt, state, opt)

    if s.pl_steps == 0 and state is None:
        evaluate(0, "start")  # the (tempered) start is a candidate too

    with Progress(total, f"fit-prior net-field {label}", unit="step", enabled=progress, initial=step) as bar:
        while step < total:
            step += 1
            rng = np.random.default_rng([s.seed, step])
            if step <= s.pl_steps:
                phase = "pl"
                for group in opt.param_groups:
                    group["lr"] = pl_step_size(s, step)
                nb, y = cells.draw(s.pl_batch, rng)
                loss = ln.pl_loss(model, nb, y)
                opt.zero_grad()
                (loss + s.lambda_ * model.penalty()).backward()
                opt.step()
                value = float(loss.detach())
            else:
                phase = "pcd"
                if step == s.pl_steps + 1:  # the PCD stage starts: its optimiser, its start, its chains
                    if s.pl_steps > 0:
                        _temper(model, s.start_beta)
                    opt = torch.optim.Adam(model.parameters(), lr=s.pcd_lr)
                    crng = np.random.default_rng([s.seed, 0])
                    if s.pcd_init == "data":
                        chains = ln.data_crops_known(train, s.pcd_chains, s.pcd_size, crng)
                    else:
                        chains = np.ascontiguousarray(crng.random((s.pcd_chains, s.pcd_size**2)) < 0.5, np.uint8)
                chain_seed = int(rng.integers(2**31 - 1))
                data = ln.data_crops_known(train, s.pcd_chains, s.pcd_size, rng)
                value = ln.pcd_update(model, opt, data, chains, s.pcd_sweeps, chain_seed, s.lambda_)
            bar.update(note=f"{phase} loss {value:.4g}")
            if step % s.eval_every == 0 or step in (s.pl_steps, total):
                evaluate(step, phase)
    model.load_arrays(best["params"])
    prior = model.prior((s.check_size, s.check_size), occupancy=share)  # an ordered field's chains do not estimate it
    arrays = net_arrays(prior)
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # type: ignore[arg-type]
    check = sampler_check(prior, s.check_sweeps, s.seed)
    path = atomic_write_bytes(out / f"net_{label}.npz", buf.getvalue())
    load_net_field(path)  # what was written must load
    prov = run_provenance(cmd, plans, validation=f"maps with index % {every} == {every - 1}")
    info = {
        "file": path.name,
        "format_version": NET_FORMAT_VERSION,
        "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "bytes": path.stat().st_size,
        "seconds_incl_reading": round(time.perf_counter() - t0, 2),
        "settings": {**s.record(), "validation": prov["validation"]},
        "provenance": prov,
        "train_maps": len(train),
        "validation_maps": len(val),
        "train_cells": cells.n_cells,
        "train_occupied_share": share,
        "chosen_step": best["step"],
        "selected_by": s.select,
        "heldout_nll" if s.select == "pl" else "unseen_nll_bits": best["nll"],
        "curve": history,
        "occupancy": float(arrays["occupancy"]),
        "sampler_check": check,
    }
    side = atomic_write_text(out / f"net_{label}.json", json.dumps(info, indent=1) + "\n")
    ckpt.unlink(missing_ok=True)
    secs = info["seconds_incl_reading"]
    say(f"{label}: wrote {path} (step {best['step']}, {s.select} score {best['nll']:.5f}; {secs} s)")
    summary = {"chosen_step": best["step"], s.select: best["nll"], "occupancy": info["occupancy"]}
    return FitResult("net-field", (path, side), prov, summary, info["seconds_incl_reading"])


def _load_start(model, s: NetFieldSettings) -> None:
    """Set ``model``'s parameters from the net-field file ``s.start`` (its window, filters, activation and pad must
    be the settings')."""
    from ogm_ppl.priors.net_field import load_net_field

    try:
        d = load_net_field(s.start)
    except ValueError as e:
        raise FitOptionError("start", str(e)) from None
    got = (d["w"], d["filters"].shape[0], d["activation"], d["pad"])
    if got != (s.w, s.hidden, s.activation, s.pad):
        raise FitOptionError(
            "start",
            f"{s.start} holds w={got[0]}, hidden={got[1]}, {got[2]}, pad {got[3]:g}; the settings ask w={s.w}, "
            f"hidden={s.hidden}, {s.activation}, pad {s.pad:g}",
        )
    model.load_arrays({k: d[k] for k in _PARAMS})


def _temper(model, beta: float) -> None:
    """Raise ``model``'s field to the power ``beta`` in place (output weights and unary bias times ``beta``)."""
    import torch

    if beta != 1.0:
        with torch.no_grad():
            model.out.mul_(beta)
            model.unary.mul_(beta)


def pl_step_size(s: NetFieldSettings, step: int) -> float:
    """The step size of pseudo-likelihood step ``step`` (1-based): ``pl_lr`` falling to ``pl_lr / 20`` on a half
    cosine over the ``pl_steps``."""
    t = (step - 1) / max(s.pl_steps - 1, 1)
    return s.pl_lr * (0.05 + 0.95 * 0.5 * (1.0 + np.cos(np.pi * t)))


def sampler_check(prior, sweeps: int, seed: int = 0) -> list[dict]:
    """What the compiled sampler draws from ``prior`` (its grid): 2 chains from the all-free, the all-occupied and
    a noise map, ``sweeps`` sweeps each, the occupied share at the end."""
    from ogm_ppl.priors.compiled.net_field_patches import net_prior_sweeps

    rng = np.random.default_rng(seed)
    K = prior.num_cells
    rows = []
    for start in ("free", "occupied", "noise"):
        m = rng.random((2, K)) < 0.5 if start == "noise" else np.full((2, K), start == "occupied")
        maps = np.ascontiguousarray(m, np.uint8)
        net_prior_sweeps(prior.compiled(), maps, int(sweeps), seed)
        rows.append({"start": start, "sweeps": int(sweeps), "occupancy": float(maps.mean())})
    return rows


def _pair(m: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(occupancy, known)`` bool arrays of a training map (a generated map: every cell known)."""
    if hasattr(m, "occupancy"):
        return np.asarray(m.occupancy, bool), np.asarray(m.known, bool)
    return np.asarray(m, bool), np.ones(np.shape(m), bool)


def _adam_arrays(opt) -> dict[str, np.ndarray]:
    out = {}
    for i, p in enumerate(opt.param_groups[0]["params"]):
        st = opt.state.get(p, {})
        if st:
            out[f"adam{i}_step"] = np.asarray(float(st["step"]), np.float64)
            out[f"adam{i}_m"] = st["exp_avg"].detach().numpy().copy()
            out[f"adam{i}_v"] = st["exp_avg_sq"].detach().numpy().copy()
    return out


def _load_adam(opt, arrays: dict) -> None:
    import torch

    for i, p in enumerate(opt.param_groups[0]["params"]):
        if f"adam{i}_step" in arrays:
            opt.state[p] = {
                "step": torch.tensor(float(arrays[f"adam{i}_step"])),
                "exp_avg": torch.from_numpy(np.array(arrays[f"adam{i}_m"], np.float64)),
                "exp_avg_sq": torch.from_numpy(np.array(arrays[f"adam{i}_v"], np.float64)),
            }


def _write_checkpoint(path: Path, state: dict, opt) -> None:
    from ogm_ppl.io import atomic_write_bytes

    arrays: dict[str, np.ndarray] = {
        "meta": np.array(
            json.dumps({k: state[k] for k in ("key", "step", "history")} | {"best": state["best"]["nll"]})
        ),
        "best_step": np.array(state["best"]["step"], np.int64),
        "chains": state["chains"],
    }
    arrays.update({f"param_{k}": v for k, v in state["params"].items()})
    arrays.update({f"best_{k}": v for k, v in state["best"]["params"].items()})
    arrays.update(_adam_arrays(opt))
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # type: ignore[arg-type]
    atomic_write_bytes(path, buf.getvalue())


def _read_checkpoint(path: Path, key: str) -> dict | None:
    """The state of an unfinished fit with the same options (``key``), or ``None``."""
    from ogm_ppl.io import read_npz

    if not path.exists():
        return None
    try:
        d = read_npz(path, "a net-field checkpoint")
        meta = json.loads(str(d["meta"]))
        if meta.get("key") != key:
            return None
        return {
            "step": int(meta["step"]),
            "history": list(meta["history"]),
            "best": {
                "nll": float(meta["best"]),
                "step": int(d["best_step"]),
                "params": {k: d[f"best_{k}"] for k in _PARAMS},
            },
            "params": {k: d[f"param_{k}"] for k in _PARAMS},
            "chains": np.ascontiguousarray(d["chains"], np.uint8),
            "adam": {k: v for k, v in d.items() if k.startswith("adam")},
        }
    except (ValueError, KeyError, TypeError):
        return None
