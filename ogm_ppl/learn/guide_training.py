r"""Train the amortised guide on a corpus's training plans, or plans of one's own: the posterior predictive with
the maps themselves as the prior (thesis Section 5.2.3; ``ogm-ppl train-guide``).

Windows of the maps (:mod:`~ogm_ppl.learn.guide_examples`), scanned by the simulator with the sensor of the
settings (:class:`~ogm_ppl.learn.guide_settings.GuideTrainingSettings`: by default the calibration protocol's 3
stops, 90 beams, 75-cell range, Gaussian range noise of 1 cell), train the guide's network
(:class:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide`, no tile phase) by minimising

.. math::
    \mathcal{L}(\phi) = \mathbb{E}_{m \sim \text{corpus},\, z \sim p(z \mid m)}
        \Bigl[-\tfrac{1}{|S(m)|} \textstyle\sum_{k \in S(m)} \log q_\phi(m_k \mid z)\Bigr]

(``S(m)``: the window's known, unpinned cells), which fits each cell's logit to the posterior marginal
``p(m_k = 1 | z)`` under the *empirical* map distribution (the forward KL of inference compilation, Le et al.
2017, with the corpus as ``p(m)``): the prediction a correlated prior tries to make of the cells no ray reached,
with a receptive field of ``1 + 2 * sum(dilations)`` cells. Each step takes a batch of ``batch`` windows of one
shape, turned by a random one of the 8 symmetries; Adam with a cosine schedule.

Every ``eval_every`` steps the validation windows (of the validation maps: every fifth map of each source, or
a validation set fixed apart from a corpus's sample, ``validation_sample``) are scored in bits per unseen
near-mapped cell; the best step's weights are kept, then a temperature ``T`` on the logits, fitted to the
validation windows' unseen cells (:func:`fit_temperature`), is folded into them.

Training checkpoints into ``OUT.ckpt.npz`` (:func:`checkpoint_path`) every ``checkpoint_every`` steps and on
Ctrl-C (at the end of the step); a second call with the same settings resumes it, bit for bit, and a checkpoint
of other settings is refused (:class:`CheckpointError`; ``fresh=True`` starts afresh). Writes ``OUT`` (the
weights, :meth:`AmortisedGuide.save`, its record naming the sources, the SHA-256 of their plans' names, the
sensor, the training and the :func:`~ogm_ppl.provenance.provenance` of the command) and the sidecar
``OUT.json`` (the record, the file's SHA-256 and the validation history), both atomically.
"""

from __future__ import annotations

import hashlib
import json
import math
import signal
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ogm_ppl.calibration.leakage import names_digest
from ogm_ppl.exceptions import CheckpointError
from ogm_ppl.inference.variational.amortised import AmortisedGuide
from ogm_ppl.io import atomic_write, atomic_write_text
from ogm_ppl.learn.guide_examples import (
    Example,
    MapSource,
    batch,
    build_set,
    corpus_source,
    files_source,
)
from ogm_ppl.learn.guide_settings import GuideTrainingSettings
from ogm_ppl.progress import Progress
from ogm_ppl.provenance import provenance

__all__ = [
    "CHECKPOINT_FORMAT",
    "GUIDE_KIND",
    "CheckpointError",
    "GuideTrainingResult",
    "checkpoint_path",
    "fit_temperature",
    "losses",
    "share",
    "train_corpus_guide",
    "windows_digest",
]

#: the record's ``kind`` of a guide trained here
GUIDE_KIND = "ogm_ppl.corpus_guide"
#: the checkpoint format this module writes and reads
CHECKPOINT_FORMAT = 1
_OBJECTIVE = "E_{m ~ corpus, z ~ p(z|m)}[-mean_k log q(m_k|z)] over known unpinned cells"


@dataclass(frozen=True)
class GuideTrainingResult:
    """What :func:`train_corpus_guide` did: ``finished`` (``False``: stopped early, ``checkpoint`` kept),
    the guide ``path`` and its ``sidecar`` (written when finished), the guide's ``record`` (its
    ``trained_for``; ``None`` when stopped), the validation ``history`` (one dict an evaluation) and the
    ``step`` reached."""

    finished: bool
    path: Path
    sidecar: Path
    checkpoint: Path
    record: dict | None
    history: list[dict]
    step: int


def share(n: int, k: int, i: int) -> int:
    """The ``i``-th of ``k`` near-equal parts of ``n`` (the first ``n % k`` one larger)."""
    return n // k + (1 if i < n % k else 0)


def losses(guide: AmortisedGuide, exs: list[Example]) -> dict[str, float]:
    """Bits per scored cell and per unseen near-mapped cell, and the unseen cells' count, over ``exs``."""
    tot = {"scored": [0.0, 0], "unseen": [0.0, 0]}
    with torch.no_grad():
        for e in exs:
            logit = guide.net(e.x[None])[0]
            nll = torch.nn.functional.binary_cross_entropy_with_logits(logit, e.y, reduction="none") / math.log(2)
            for k, m in (("scored", e.scored), ("unseen", e.unseen)):
                tot[k][0] += float(nll[m].sum())
                tot[k][1] += int(m.sum())
    return {
        "bits_per_cell": tot["scored"][0] / max(tot["scored"][1], 1),
        "bits_per_unseen_cell": tot["unseen"][0] / max(tot["unseen"][1], 1),
        "unseen_cells": tot["unseen"][1],
    }


def windows_digest(exs: list[Example]) -> str:
    """SHA-256 of windows' truths and unseen-cell masks (shapes and bytes, in order): which validation windows a
    guide was scored on, so that guides claiming one validation set can be checked to share it."""
    h = hashlib.sha256()
    for e in exs:
        for t in (e.y, e.unseen):
            a = t.numpy()
            h.update(repr(a.shape).encode())
            h.update(np.ascontiguousarray(a.astype(np.uint8)).tobytes())
    return h.hexdigest()


def fit_temperature(guide: AmortisedGuide, exs: list[Example]) -> float:
    """The temperature ``T`` in ``[1/4, 4]`` minimising the validation NLL of the unseen near-mapped cells under
    ``sigmoid(logit / T)`` (temperature scaling, Guo et al. 2017; a golden-section search on ``log T``), and
    folded into the guide: the head and the skip are linear in the logit, so both are divided by ``T``."""
    with torch.no_grad():
        logit = torch.cat([guide.net(e.x[None])[0][e.unseen] for e in exs]).double()
        y = torch.cat([e.y[e.unseen] for e in exs]).double()

    def nll(log_t: float) -> float:
        return float(torch.nn.functional.binary_cross_entropy_with_logits(logit / math.exp(log_t), y))

    a, b = math.log(0.25), math.log(4.0)
    g = (math.sqrt(5) - 1) / 2
    for _ in range(60):
        c, d = b - g * (b - a), a + g * (b - a)
        a, b = (a, d) if nll(c) < nll(d) else (c, b)
    t = math.exp((a + b) / 2)
    with torch.no_grad():
        for layer in (guide.net.head, guide.net.skip):
            layer.weight /= t
            layer.bias /= t
    return t


# ------------------------------------------------------------------ checkpoints
def checkpoint_path(out: Path) -> Path:
    """Where the training of ``out`` keeps its checkpoint: ``out`` with ``.ckpt.npz``."""
    return out.with_name(out.stem + ".ckpt.npz")


@dataclass
class _Loop:
    """What the training loop carries from step to step."""

    guide: AmortisedGuide
    opt: torch.optim.Adam
    sched: torch.optim.lr_scheduler.CosineAnnealingLR
    rng: np.random.Generator
    best: dict
    best_state: dict | None
    history: list[dict]


def _save_checkpoint(path: Path, key: str, step: int, seconds: float, loop: _Loop) -> None:
    """Everything the loop carries after ``step`` (weights, Adam's moments, the schedule, both generators, the
    validation-best weights and the history), as plain arrays and JSON (never pickled), written atomically."""
    arrays: dict[str, np.ndarray] = {f"net.{k}": t.detach().numpy() for k, t in loop.guide.net.state_dict().items()}
    if loop.best_state is not None:
        arrays.update({f"best.{k}": t.numpy() for k, t in loop.best_state.items()})
    osd = loop.opt.state_dict()
    for i, st in osd["state"].items():
        for k, t in st.items():
            arrays[f"opt.{i}.{k}"] = torch.as_tensor(t).numpy()
    meta = {
        "format": CHECKPOINT_FORMAT,
        "step": step,
        "seconds": seconds,
        "settings": key,
        "param_groups": osd["param_groups"],
        "scheduler": loop.sched.state_dict(),
        "rng": loop.rng.bit_generator.state,
        "best": loop.best,
        "history": loop.history,
    }
    arrays["torch_rng"] = torch.get_rng_state().numpy()
    arrays["meta"] = np.array(json.dumps(meta, allow_nan=True))
    with atomic_write(path) as f:
        np.savez(f, **arrays)  # type: ignore[arg-type]  # numpy stub: **arrays could fill allow_pickle


def _load_checkpoint(path: Path, key: str, loop: _Loop) -> tuple[int, float]:
    """Restore what :func:`_save_checkpoint` wrote into ``loop`` and torch's generator; returns ``(first step to
    run, seconds spent)``. A checkpoint of other settings (``key``), or one that cannot be read, is refused
    (:class:`CheckpointError` naming the path)."""
    hint = "delete it or pass --fresh (fresh=True)"
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in z.files if k != "meta"}
    except Exception as e:  # BadZipFile, OSError, ValueError, KeyError, JSONDecodeError
        raise CheckpointError(f"{path}: not a readable checkpoint ({type(e).__name__}: {e}); {hint}") from None
    if meta.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path}: checkpoint format {meta.get('format')!r}, expected {CHECKPOINT_FORMAT}; {hint}")
    try:
        mine, theirs = json.loads(key), json.loads(meta["settings"])
    except (KeyError, TypeError, ValueError) as e:
        raise CheckpointError(f"{path}: damaged checkpoint ({type(e).__name__}: {e}); {hint}") from None
    differ = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
    if differ:
        raise CheckpointError(
            f"{path}: checkpoint of another training (settings that differ: {', '.join(differ)}); "
            "rerun with its settings, or pass --fresh (fresh=True) to start afresh"
        )
    try:
        loop.guide.net.load_state_dict(
            {k[4:]: torch.from_numpy(v.copy()) for k, v in arrays.items() if k.startswith("net.")}
        )
        state: dict = {}
        for k, v in arrays.items():
            if k.startswith("opt."):
                _, i, name = k.split(".", 2)
                state.setdefault(int(i), {})[name] = torch.from_numpy(v.copy())
        loop.opt.load_state_dict({"state": state, "param_groups": meta["param_groups"]})
        loop.sched.load_state_dict(meta["scheduler"])
        loop.rng.bit_generator.state = meta["rng"]
        torch.set_rng_state(torch.from_numpy(arrays["torch_rng"].copy()))
        loop.best, loop.history = meta["best"], meta["history"]
        first, seconds = int(meta["step"]) + 1, float(meta["seconds"])
    except Exception as e:
        raise CheckpointError(f"{path}: damaged checkpoint ({type(e).__name__}: {e}); {hint}") from None
    loop.best_state = {k[5:]: torch.from_numpy(v.copy()) for k, v in arrays.items() if k.startswith("best.")} or None
    return first, seconds


# ------------------------------------------------------------------ training
def _sources(s: GuideTrainingSettings) -> list[MapSource]:
    out = [corpus_source(c, s.sample, s.sample_seed, s.validation_sample, s.validation_after) for c in s.corpus]
    if s.plan_files:
        out.append(files_source(s.plan_files, s.pixel_size))
    return out


def _say(progress: bool, text: str) -> None:
    if progress:
        print(text, file=sys.stderr, flush=True)


def train_corpus_guide(
    settings: GuideTrainingSettings,
    out: Path | str,
    *,
    progress: bool = True,
    stop_after: int | None = None,
    fresh: bool = False,
    command: str | None = None,
) -> GuideTrainingResult:
    """Train a guide as the module docstring says and write it to ``out`` (``.npz``) and ``out.json``.

    Args:
        settings: what to train on and how (checked when built).
        out: the guide file; its checkpoint is ``checkpoint_path(out)``.
        progress: progress lines and the validation losses on stderr.
        stop_after: stop (as Ctrl-C does) after that many steps of this call, leaving the checkpoint.
        fresh: ignore a checkpoint at ``checkpoint_path(out)`` and start afresh.
        command: the command recorded in the provenance (default :meth:`GuideTrainingSettings.command`).

    Returns:
        :class:`GuideTrainingResult`; ``finished`` is ``False`` when stopped (``stop_after`` or Ctrl-C).

    Raises:
        CheckpointError: a checkpoint of other settings, or an unreadable one (unless ``fresh``).
        ~ogm_ppl.learn.guide_examples.TooFewWindowsError: the maps give too few usable windows.
        ~ogm_ppl.calibration.leakage.LeakageError: a corpus's tables' training set cannot be rebuilt.
        ~ogm_ppl.datasets.plan_files.PlanFileError: a plan file is missing or unreadable.
    """
    s = settings
    out = Path(out)
    if stop_after is not None and stop_after < 1:
        raise ValueError(f"stop_after must be at least 1, got {stop_after}")
    command = s.command(out) if command is None else command
    torch.manual_seed(s.seed)
    sources = _sources(s)
    name = s.label
    t0 = time.perf_counter()
    tr: list[Example] = []
    val: list[Example] = []
    records: dict[str, dict] = {}
    for i, src in enumerate(sources):
        tr_names, val_names = src.split()
        _say(progress, f"{src.label}: {len(tr_names)} training plans, {len(val_names)} validation plans")
        if not tr_names:
            raise ValueError(f"{src.label}: no training plans (every fifth plan validates; give 2 or more)")
        seed = s.seed + 10 * i
        drawn: set[str] = set()
        tr += build_set(src, tr_names, share(s.examples, len(sources), i), s, seed, "training", progress, drawn)
        val += build_set(src, val_names, share(s.val, len(sources), i), s, seed + 1, "validation", progress)
        records[src.label] = {
            "training_plans": len(tr_names),
            "training_plans_drawn": len(drawn),
            "validation_plans": len(val_names),
            "plan_names_sha256": names_digest(tr_names + val_names),
            **src.record,
        }
    t_data = time.perf_counter() - t0
    key = json.dumps({**json.loads(s.fingerprint()), "sources": records}, sort_keys=True)
    by_shape: dict[tuple, list[Example]] = {}
    for e in tr:
        by_shape.setdefault(tuple(e.y.shape), []).append(e)
    shapes = list(by_shape)
    weights = np.array([len(by_shape[sh]) for sh in shapes], float)
    guide = AmortisedGuide(channels=s.channels, dilations=s.dilations, phase=(0, 0), delta="p21", seed=s.seed)
    opt = torch.optim.Adam(guide.net.parameters(), lr=s.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=s.steps)
    loop = _Loop(guide, opt, sched, np.random.default_rng(s.seed + 2), {"bits_per_unseen_cell": math.inf}, None, [])
    ckpt = checkpoint_path(out)
    first, spent = 1, 0.0
    if ckpt.exists() and not fresh:
        first, spent = _load_checkpoint(ckpt, key, loop)
        _say(progress, f"resuming from {ckpt} at step {first - 1}/{s.steps}")
    stop = {"flag": False}

    def on_sigint(signum, frame):
        stop["flag"] = True

    # Ctrl-C stops at the end of a step, with a checkpoint (a handler can be set in the main thread only)
    in_main = threading.current_thread() is threading.main_thread()
    old_handler = signal.signal(signal.SIGINT, on_sigint) if in_main else None
    t1 = time.perf_counter() - spent
    step = first - 1
    rng = loop.rng
    try:
        with Progress(s.steps, "training steps", unit="step", enabled=progress, initial=first - 1) as bar:
            for step in range(first, s.steps + 1):
                sh = shapes[int(rng.choice(len(shapes), p=weights / weights.sum()))]
                pool = by_shape[sh]
                idx = rng.choice(len(pool), size=min(s.batch, len(pool)), replace=False)
                x, y, scored, _ = batch([pool[i] for i in idx], int(rng.integers(8)))
                logit = guide.net(x)
                nll = torch.nn.functional.binary_cross_entropy_with_logits(logit, y, reduction="none")
                loss = (nll * scored).sum() / scored.sum().clamp(min=1)
                opt.zero_grad()
                loss.backward()
                opt.step()
                sched.step()
                if step % s.eval_every == 0 or step == s.steps:
                    v: dict = losses(guide, val)
                    v["step"] = step
                    v["train_bits_per_cell"] = loss.item() / math.log(2)
                    loop.history.append(v)
                    mark = ""
                    if v["bits_per_unseen_cell"] < loop.best["bits_per_unseen_cell"]:
                        loop.best, mark = v, " *"
                        loop.best_state = {k: t.detach().clone() for k, t in guide.net.state_dict().items()}
                    _say(
                        progress,
                        f"step {step}/{s.steps}: train {v['train_bits_per_cell']:.3f} bits/cell, validation "
                        f"{v['bits_per_cell']:.3f} bits/cell, {v['bits_per_unseen_cell']:.3f} bits/unseen cell"
                        f"{mark} ({time.perf_counter() - t1:.0f} s)",
                    )
                bar.update()
                done = step == s.steps
                stopped = stop["flag"] or (stop_after is not None and step - first + 1 >= stop_after)
                if stopped or (not done and step % s.checkpoint_every == 0):
                    _save_checkpoint(ckpt, key, step, time.perf_counter() - t1, loop)
                if stopped and not done:
                    _say(progress, f"interrupted at step {step}/{s.steps}: checkpoint {ckpt}; the same command resumes")
                    return GuideTrainingResult(False, out, out.with_suffix(".json"), ckpt, None, loop.history, step)
    finally:
        if in_main:
            signal.signal(signal.SIGINT, old_handler)
    assert loop.best_state is not None
    guide.net.load_state_dict(loop.best_state)
    best = loop.best
    temperature = 1.0
    if s.temperature:
        temperature = fit_temperature(guide, val)
        after = losses(guide, val)
        _say(
            progress,
            f"temperature {temperature:.3f}: validation {best['bits_per_unseen_cell']:.3f} -> "
            f"{after['bits_per_unseen_cell']:.3f} bits/unseen cell",
        )
        best = {**best, **after, "before_temperature": best["bits_per_unseen_cell"]}
    meta = _record(s, name, records, best, temperature, t_data, time.perf_counter() - t1, command)
    meta["validation"]["windows_sha256"] = windows_digest(val)
    guide.save(out, meta)
    side = out.with_suffix(".json")
    digest = hashlib.sha256(out.read_bytes()).hexdigest()
    record = {"file": out.name, "sha256": digest, **meta, "history": loop.history}
    atomic_write_text(side, json.dumps(record, indent=1))
    ckpt.unlink(missing_ok=True)  # the artefact is written: the checkpoint is spent
    kept = f"kept step {best['step']}, {best['bits_per_unseen_cell']:.3f} bits/unseen cell"
    _say(progress, f"wrote {out} and {side}: {kept}")
    return GuideTrainingResult(True, out, side, ckpt, meta, loop.history, step)


def _record(
    s: GuideTrainingSettings,
    name: str,
    records: dict[str, dict],
    best: dict,
    temperature: float,
    t_data: float,
    t_train: float,
    command: str,
) -> dict:
    """The guide's record (its ``trained_for``): the sources, the sensor, the training, the validation losses."""
    return {
        "kind": GUIDE_KIND,
        "corpus": name,
        **(records[name] if name in records and len(records) == 1 else {"corpora": records}),
        "scans": {
            "whole_map": bool(s.scan_whole_map),
            "poses": s.poses,
            "beams": s.beams,
            "range_cells": s.range_cells,
            "sigma_cells": s.sigma,
            "window": s.window,
            **({"drive_step_cells": list(s.drive), "fov_degrees": s.fov} if s.drive else {}),
            **({"plan_range_cells": s.plan_range_cells} if s.plan_range_cells else {}),
        },
        "training": {
            "objective": _OBJECTIVE,
            "examples": s.examples,
            "validation_examples": s.val,
            "steps": s.steps,
            "batch": s.batch,
            "lr": s.lr,
            "schedule": "cosine",
            "seed": s.seed,
            "kept_step": best["step"],
            "chosen_by": "validation bits per unseen near-mapped cell",
            "temperature": temperature,
        },
        "validation": {
            k: best[k]
            for k in ("bits_per_cell", "bits_per_unseen_cell", "unseen_cells", "before_temperature")
            if k in best
        },
        "seconds": {"data": round(t_data, 1), "training": round(t_train, 1)},
        "torch": torch.__version__,
        "provenance": provenance(command),
    }
