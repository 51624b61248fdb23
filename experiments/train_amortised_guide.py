"""Train the amortised guide q(m | z) by inference compilation (Le et al. 2017).

Every step draws one random scene (grid of 24..40 x 24..40 cells, 1..6 poses of 120-beam 360 degree
scans, maximum range 12 cells, ``GaussianRange(1.0)``), then a batch of maps from the learned prior given
that the pose cells are free and readings from the forward sensor model: ``(m, z) ~ p(m) p(z | m)``, the
model's own joint. The loss is ``-log q(m | z)`` averaged over the batch (the CSIS objective, forward KL
averaged over data). Held-out loss: scenes and maps from a separate seed stream, never trained on.

    python experiments/train_amortised_guide.py            # 4-7 min on 2 shared cores; writes the shipped artefact
    python experiments/train_amortised_guide.py --steps 50 --out /tmp/g.npz    # a smoke run

Writes ``ogm_ppl/fitted/guide_amortised.npz`` and ``guide_amortised.json`` (settings, held-out loss, time).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl import GaussianRange
from ogm_ppl.inference.variational.amortised import SHIPPED_GUIDE, AmortisedGuide, random_scene
from ogm_ppl.io import atomic_write_text
from ogm_ppl.priors.named import prior_by_name


def draw(args, rng: np.random.Generator, priors: dict, batch: int):
    """One scene and ``batch`` joint draws ``(m, z)`` of its model."""
    shape = (int(rng.integers(args.min_size, args.max_size + 1)), int(rng.integers(args.min_size, args.max_size + 1)))
    if shape not in priors:
        priors[shape] = prior_by_name(args.prior, shape)
    poses = int(rng.integers(1, args.max_poses + 1))
    scene = random_scene(priors[shape], shape, poses, args.beams, args.range_cells, GaussianRange(args.sigma), rng)
    model = scene.model()
    gen = torch.Generator().manual_seed(int(rng.integers(2**62)))
    maps = model.prior.sample_given_free(model.known_free, (batch,), generator=gen)
    z = model.simulate_readings(maps, generator=gen)
    return model, maps, z


def heldout_loss(guide: AmortisedGuide, val: list) -> tuple[float, float, float]:
    """(nats per map, bits per latent cell, bits per latent cell of the prior-marginal guess)."""
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


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--prior", default="patch3:generated")
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--channels", type=int, default=24)
    ap.add_argument("--dilations", default="1,2,4,1")
    ap.add_argument("--min-size", type=int, default=24)
    ap.add_argument("--max-size", type=int, default=40)
    ap.add_argument("--max-poses", type=int, default=6)
    ap.add_argument("--beams", type=int, default=120)
    ap.add_argument("--range-cells", type=float, default=12.0)
    ap.add_argument("--sigma", type=float, default=1.0)
    ap.add_argument("--val-scenes", type=int, default=48)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(SHIPPED_GUIDE))
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    from tqdm.auto import tqdm

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    train_ss, val_ss = np.random.SeedSequence(args.seed).spawn(2)  # disjoint streams: held-out never trained on
    rng, vrng = np.random.default_rng(train_ss), np.random.default_rng(val_ss)
    priors: dict = {}
    val = [draw(args, vrng, priors, 4) for _ in range(args.val_scenes)]
    dil = tuple(int(d) for d in args.dilations.split(","))
    phase = (3, 3) if args.prior.split(":")[0] in ("patch3", "patch3_999") else (0, 0)
    guide = AmortisedGuide(channels=args.channels, dilations=dil, phase=phase, seed=args.seed)
    with torch.no_grad():  # start at the prior's occupied share
        lam = float(getattr(prior_by_name(args.prior, (6, 6)), "mean_occupancy", 0.3))
        guide.net.head.bias.fill_(math.log(lam / (1 - lam)))
    opt = torch.optim.Adam(guide.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, args.steps, eta_min=args.lr / 30)
    start = heldout_loss(guide, val)
    t0 = time.perf_counter()
    trace = []
    bar = tqdm(range(args.steps), desc="csis", unit="step", mininterval=5.0)
    for step in bar:
        model, maps, z = draw(args, rng, priors, args.batch)
        loss = guide.csis_loss(model, maps, z) / len(model.latent)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        trace.append(float(loss.detach()) / math.log(2))
        if step % 50 == 0:
            bar.set_postfix(bits_per_cell=f"{np.mean(trace[-50:]):.4f}")
    seconds = time.perf_counter() - t0
    end = heldout_loss(guide, val)
    meta = {
        "prior": args.prior,
        "sensor": repr(GaussianRange(args.sigma)),
        "beams": args.beams,
        "max_range_cells": args.range_cells,
        "poses": [1, args.max_poses],
        "sizes": [args.min_size, args.max_size],
    }
    out = Path(args.out)
    guide.save(out, meta)
    data = out.read_bytes()
    record = {
        "file": out.name,
        "sha256": hashlib.sha256(data).hexdigest(),
        "bytes": len(data),
        "parameters": sum(p.numel() for p in guide.parameters()),
        "architecture": {"channels": args.channels, "dilations": list(dil), "phase": list(phase), "delta": "p21"},
        "trained_for": meta,
        "training": {
            "objective": "E_p(m,z)[-log q(m|z)] (CSIS / inference compilation, Le et al. 2017)",
            "steps": args.steps,
            "batch": args.batch,
            "lr": args.lr,
            "schedule": "cosine",
            "seed": args.seed,
            "threads": args.threads,
            "seconds": round(seconds, 1),
            "maps_seen": args.steps * args.batch,
            "train_bits_per_cell_last100": float(np.mean(trace[-100:])),
        },
        "heldout": {
            "scenes": args.val_scenes,
            "maps_per_scene": 4,
            "seed_stream": "SeedSequence(seed).spawn(2)[1]",
            "nats_per_map_before": start[0],
            "nats_per_map": end[0],
            "bits_per_cell_before": start[1],
            "bits_per_cell": end[1],
            "bits_per_cell_prior_share_guess": end[2],
            "bits_per_cell_uniform_guess": 1.0,
        },
    }
    atomic_write_text(out.with_suffix(".json"), json.dumps(record, indent=1) + "\n")
    print(json.dumps(record["heldout"], indent=1))
    print(f"trained in {seconds:.0f} s; wrote {out} ({len(data)} bytes)")


if __name__ == "__main__":
    main()
