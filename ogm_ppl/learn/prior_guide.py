r"""Train the amortised guide ``q(m | z)`` of a learned prior by inference compilation (Le et al. 2017; thesis
Section 2.6): the shipped ``guide_amortised.npz``.

Every step draws one random scene (a grid of ``min_size..max_size`` cells a side, ``1..max_poses`` poses of
``beams``-beam 360 degree scans, maximum range ``range_cells``, ``GaussianRange(sigma)``;
:func:`~ogm_ppl.inference.variational.amortised_scenes.random_scene`), then a batch of maps from the prior given that
the pose cells are free and readings from the forward sensor model: ``(m, z) ~ p(m) p(z | m)``, the model's own
joint. The loss, :meth:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide.csis_loss` per latent cell,

.. math::
    \mathcal{L}(\phi) = \mathbb{E}_{p(m, z)}\bigl[-\log q_\phi(m \mid z)\bigr],

is the forward KL averaged over data (Adam, cosine schedule down to ``lr / 30``). Held-out loss: scenes and maps
from a separate seed stream (``SeedSequence(seed).spawn(2)[1]``), never trained on.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ogm_ppl.inference.variational.amortised import AmortisedGuide, random_scene
from ogm_ppl.io import atomic_write_text
from ogm_ppl.learn.guide_settings import GuideSettingsError
from ogm_ppl.priors.named import prior_by_name
from ogm_ppl.progress import Progress
from ogm_ppl.provenance import provenance
from ogm_ppl.sensors import GaussianRange

__all__ = ["PriorGuideResult", "PriorGuideSettings", "heldout_loss", "train_prior_guide"]


@dataclass(frozen=True)
class PriorGuideSettings:
    """Every option of a prior's guide training (module docstring); ``threads``: torch's threads while it runs.

    Raises:
        GuideSettingsError: an option out of range (named, with its limit).
    """

    prior: str = "patch3:generated"
    steps: int = 1500
    batch: int = 16
    lr: float = 3e-3
    channels: int = 24
    dilations: tuple[int, ...] = (1, 2, 4, 1)
    min_size: int = 24
    max_size: int = 40
    max_poses: int = 6
    beams: int = 120
    range_cells: float = 12.0
    sigma: float = 1.0
    val_scenes: int = 48
    seed: int = 0
    threads: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "dilations", tuple(self.dilations))
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            flag = "--" + f.name.replace("_", "-")
            least = 0 if f.name == "seed" else 1
            if f.type == "int" and (isinstance(v, bool) or not isinstance(v, int) or v < least):
                raise GuideSettingsError(f.name, f"{flag} must be a whole number of at least {least}, got {v!r}")
            if f.type == "float" and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise GuideSettingsError(f.name, f"{flag} must be finite and above 0, got {v}")
        if self.min_size > self.max_size:
            raise GuideSettingsError("min_size", f"--min-size {self.min_size} is above --max-size {self.max_size}")
        if not self.dilations or any(isinstance(d, bool) or not isinstance(d, int) or d < 1 for d in self.dilations):
            raise GuideSettingsError("dilations", f"--dilations must be whole numbers >= 1, got {self.dilations}")


@dataclass(frozen=True)
class PriorGuideResult:
    """The guide ``path``, its ``sidecar`` JSON and the ``record`` written there."""

    path: Path
    sidecar: Path
    record: dict


def _draw(s: PriorGuideSettings, rng: np.random.Generator, priors: dict, batch: int):
    """One scene and ``batch`` joint draws ``(m, z)`` of its model."""
    shape = (int(rng.integers(s.min_size, s.max_size + 1)), int(rng.integers(s.min_size, s.max_size + 1)))
    if shape not in priors:
        priors[shape] = prior_by_name(s.prior, shape)
    poses = int(rng.integers(1, s.max_poses + 1))
    scene = random_scene(priors[shape], shape, poses, s.beams, s.range_cells, GaussianRange(s.sigma), rng)
    model = scene.model()
    gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
    maps = model.prior.sample_given_free(model.known_free, (batch,), generator=gen)
    z = model.simulate_readings(maps, generator=gen)
    return model, maps, z


def heldout_loss(guide: AmortisedGuide, val: list) -> tuple[float, float, float]:
    """(nats per map, bits per latent cell, bits per latent cell of the prior-marginal guess) over ``val``,
    a list of ``(model, maps, z)``."""
    nats, cells, base = 0.0, 0, 0.0
    with torch.no_grad():
        for model, maps, z in val:
            n = len(maps)
            nats += float(guide.csis_loss(model, maps, z)) * n
            cells += len(model.latent) * n
            lam = float(maps[:, model.latent].mean())
            lam = min(max(lam, 1e-6), 1 - 1e-6)
            m = maps[:, model.latent]
            base += float(-(m * math.log(lam) + (1 - m) * math.log(1 - lam)).sum())
    return (
        nats / len(val) / (sum(len(v[1]) for v in val) / len(val)),
        nats / cells / math.log(2),
        base / cells / math.log(2),
    )


def train_prior_guide(
    settings: PriorGuideSettings, out: Path | str, *, progress: bool = True, command: str | None = None
) -> PriorGuideResult:
    """Train the guide of ``settings.prior`` (module docstring) and write ``out`` (:meth:`AmortisedGuide.save`)
    and ``out.json`` (settings, held-out loss before and after, time, the :func:`~ogm_ppl.provenance.provenance`
    of ``command``, default this process's command line), both atomically."""
    s, out = settings, Path(out)
    threads = torch.get_num_threads()
    torch.set_num_threads(s.threads)
    try:
        return _train(s, out, progress, command)
    finally:
        torch.set_num_threads(threads)


def _train(s: PriorGuideSettings, out: Path, progress: bool, command: str | None) -> PriorGuideResult:
    torch.manual_seed(s.seed)
    train_ss, val_ss = np.random.SeedSequence(s.seed).spawn(2)  # disjoint streams: held-out never trained on
    rng, vrng = np.random.default_rng(train_ss), np.random.default_rng(val_ss)
    priors: dict = {}
    val = [_draw(s, vrng, priors, 4) for _ in range(s.val_scenes)]
    phase = (3, 3) if s.prior.split(":")[0] in ("patch3", "patch3_999") else (0, 0)
    guide = AmortisedGuide(channels=s.channels, dilations=s.dilations, phase=phase, seed=s.seed)
    with torch.no_grad():  # start at the prior's occupied share
        lam = float(getattr(prior_by_name(s.prior, (6, 6)), "mean_occupancy", 0.3))
        guide.net.head.bias.fill_(math.log(lam / (1 - lam)))
    opt = torch.optim.Adam(guide.parameters(), lr=s.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, s.steps, eta_min=s.lr / 30)
    start = heldout_loss(guide, val)
    t0 = time.perf_counter()
    trace = []
    with Progress(s.steps, "csis", unit="step", enabled=progress, after=10.0) as bar:
        for step in range(s.steps):
            model, maps, z = _draw(s, rng, priors, s.batch)
            loss = guide.csis_loss(model, maps, z) / len(model.latent)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            trace.append(float(loss.detach()) / math.log(2))
            bar.update(note=f"{np.mean(trace[-50:]):.4f} bits/cell" if step % 50 == 0 else "")
    seconds = time.perf_counter() - t0
    end = heldout_loss(guide, val)
    meta = {
        "prior": s.prior,
        "sensor": repr(GaussianRange(s.sigma)),
        "beams": s.beams,
        "max_range_cells": s.range_cells,
        "poses": [1, s.max_poses],
        "sizes": [s.min_size, s.max_size],
    }
    guide.save(out, meta)
    data = out.read_bytes()
    record = {
        "file": out.name,
        "sha256": hashlib.sha256(data).hexdigest(),
        "bytes": len(data),
        "parameters": sum(p.numel() for p in guide.parameters()),
        "architecture": {"channels": s.channels, "dilations": list(s.dilations), "phase": list(phase), "delta": "p21"},
        "trained_for": meta,
        "training": {
            "objective": "E_p(m,z)[-log q(m|z)] (CSIS / inference compilation, Le et al. 2017)",
            "steps": s.steps,
            "batch": s.batch,
            "lr": s.lr,
            "schedule": "cosine",
            "seed": s.seed,
            "threads": s.threads,
            "seconds": round(seconds, 1),
            "maps_seen": s.steps * s.batch,
            "train_bits_per_cell_last100": float(np.mean(trace[-100:])),
        },
        "heldout": {
            "scenes": s.val_scenes,
            "maps_per_scene": 4,
            "seed_stream": "SeedSequence(seed).spawn(2)[1]",
            "nats_per_map_before": start[0],
            "nats_per_map": end[0],
            "bits_per_cell_before": start[1],
            "bits_per_cell": end[1],
            "bits_per_cell_prior_share_guess": end[2],
            "bits_per_cell_uniform_guess": 1.0,
        },
        "provenance": provenance(command),
    }
    side = atomic_write_text(out.with_suffix(".json"), json.dumps(record, indent=1) + "\n")
    if progress:
        print(f"trained in {seconds:.0f} s; wrote {out} ({len(data)} bytes)", file=sys.stderr, flush=True)
    return PriorGuideResult(out, side, record)
