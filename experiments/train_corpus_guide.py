r"""Train the amortised guide on a corpus's own training plans: the posterior predictive with the corpus
itself as the prior.

``experiments/train_amortised_guide.py`` compiles inference for a *learned* prior (maps drawn from a patch
table). Here the maps are the corpus's training plans: windows of them, scanned by the stop-and-scan
simulator with the sensor of ``experiments/calibration.py`` (3 stops, 90 beams, 75-cell range, Gaussian
range noise of 1 cell). Minimising

.. math::
    \mathcal{L}(\phi) = \mathbb{E}_{m \sim \text{corpus},\, z \sim p(z \mid m)}
        \Bigl[-\tfrac{1}{|S(m)|} \textstyle\sum_{k \in S(m)} \log q_\phi(m_k \mid z)\Bigr]

(``S(m)``: the window's known, unpinned cells) fits each cell's logit to the posterior marginal
``p(m_k = 1 | z)`` under the *empirical* map distribution (the forward KL of inference compilation, Le et al.
2017, with the corpus as ``p(m)``): the prediction a correlated prior tries to make of the cells no ray reached,
with a receptive field of ``1 + 2 * sum(dilations)`` cells instead of a 3 x 3 or 5 x 5 table. Training windows
are drawn at random (half at the window with the most wall-side cells, as the calibration experiment crops,
half anywhere with at least 200 known free cells) and turned by a random one of the 8 symmetries each step.

``--scan-whole-map`` scans each whole map along a planned route instead and crops ``--crops`` windows of its
features (the Table 6.4 simulator: ``--corpus generated --poses 0 --beams 720 --sigma 3``), so the guide learns
the evidence of a route through the whole building; with ``--drive S1 S2 ...`` it scans while driving the
route, a pose every ``S`` cells of path (``S`` drawn per map) scanning ``--fov`` degrees ahead: a real log's
evidence, at several densities (``--plan-range-cells``: the range the planner places its stops for; a stop must
show 2 % of the sensor's disc, so planned for a 400-cell range most house plans get one stop); the generated
corpus's maps are those its tables counted (``iter_corpus`` with the recorded seed, rebuilt by name).

Only the plans the corpus's shipped tables were learned from are used (``training_set`` of
``calibration.py``, rebuilt from their provenance; every fifth one held out as validation plans that pick the
step kept, then a temperature on the logits fitted to their unseen near-mapped cells, folded into the weights),
so the calibration experiment's leakage check covers the guide as it covers the tables. The
artefact records the corpus and the SHA-256 of its training plans' names; ``calibration.py --guides`` refuses
a guide whose record does not match the tables' training set.

Several corpora (``--corpus houseexpo ipa``) give one guide learned on all their training plans, the
``--examples`` and ``--val`` windows shared evenly between them: ``guide_houseexpo+ipa.npz``, whose record
holds each corpus's training set, so a test plan of either corpus is checked against its own.

    python experiments/train_corpus_guide.py --corpus houseexpo        # 7-15 min on 2 cores
    python experiments/train_corpus_guide.py --corpus houseexpo ipa --examples 1200 --val 120 --steps 3000
    python experiments/train_corpus_guide.py --corpus ipa --steps 20 --examples 16 --out /tmp/g.npz   # smoke
    python experiments/train_corpus_guide.py --corpus generated --scan-whole-map --poses 0 --beams 720 --sigma 3 \
        --window 128 --examples 640 --val 64 --crops 10 --dilations 1 2 4 8 16 16 1 --steps 1500   # Table 6.4

Training checkpoints into ``OUT.ckpt.npz`` every ``--checkpoint-every`` steps and on Ctrl-C (at the end of the
step); the same command resumes it, bit for bit, and a checkpoint of other settings is refused (``--fresh``
starts afresh). Writes ``ogm_ppl/fitted/guide_<corpus>.npz`` (``guide_<c1>+<c2>.npz`` for several: the weights,
:meth:`AmortisedGuide.save`) and its JSON sidecar (settings, training and validation losses, the time).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import ogm_ppl.calibration as calibration  # the protocol, windows and training sets
from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.datasets import floorplans as fp
from ogm_ppl.datasets.stop_and_scan import stop_and_scan
from ogm_ppl.inference.variational.amortised import AmortisedGuide, evidence_features
from ogm_ppl.io import atomic_write, atomic_write_text
from ogm_ppl.metrics import near_mapped_mask
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.priors.tables import FITTED_DIR

CORPORA: tuple[str, ...] = ("houseexpo", "ipa", "dungeon", "generated")
GUIDE_KIND = "ogm_ppl.corpus_guide"
GUIDE_JOIN = calibration.GUIDE_JOIN


@dataclass
class Example:
    """One training window: features ``C x H x W`` float32, truth ``H x W`` float32 (1 = occupied), the
    scored cells ``S`` and the unseen near-mapped cells (``H x W`` bool each)."""

    x: torch.Tensor
    y: torch.Tensor
    scored: torch.Tensor
    unseen: torch.Tensor


def split_plans(corpus: str) -> tuple[list[str], list[str]]:
    """``(training, validation)`` plans: the tables' training set in sorted order, every fifth one held out."""
    names = sorted(calibration.training_set(corpus))
    val = names[::5]
    return [n for n in names if n not in set(val)], val


def _random_window(occ, known, window, rng) -> tuple[int, int] | None:
    H, W = occ.shape
    h, w = min(window, H), min(window, W)
    for _ in range(20):
        r = int(rng.integers(0, H - h + 1))
        c = int(rng.integers(0, W - w + 1))
        if (known[r : r + h, c : c + w] & ~occ[r : r + h, c : c + w]).sum() >= 200:
            return r, c
    return None


def scanned(grid: Grid, scans, sigma: float, known: np.ndarray) -> tuple[torch.Tensor, np.ndarray, np.ndarray]:
    """The guide's input for ``scans`` of ``grid`` (:func:`evidence_features`, no tile phase, ``C x H x W``),
    the pinned cells and the unseen near-mapped cells (``H x W`` bool: known, within 10 cells of a reached
    cell, not reached)."""
    rays = raycast(grid, scans)
    model = OccupancyModel(grid, rays, GaussianRange(sigma), IndependentPrior(0.5, grid.num_cells))
    reached = rays.reached().reshape(grid.shape)
    pinned = model.known_free.numpy().reshape(grid.shape)
    return evidence_features(model, phase=(0, 0)), pinned, near_mapped_mask(reached, 10.0) & known & ~reached


def make_example(plan, window: int, args, rng: np.random.Generator) -> Example | None:
    """One window of ``plan`` (a :class:`Plan`), scanned as the calibration
    experiment scans its test maps but with a fresh seed; ``None`` when the window holds fewer than 200 known
    free cells or no stop with the simulator's clearance."""
    occ, known = plan.occupancy, plan.known
    if rng.random() < 0.5:
        rc = calibration.choose_window(occ, known, window)
    else:
        rc = _random_window(occ, known, window, rng)
    if rc is None:
        return None
    r0, c0 = rc
    h, w = min(window, occ.shape[0]), min(window, occ.shape[1])
    truth, kn = occ[r0 : r0 + h, c0 : c0 + w], known[r0 : r0 + h, c0 : c0 + w]
    if (kn & ~truth).sum() < 200:
        return None
    grid = Grid(truth.shape, resolution=plan.resolution or 0.05)
    try:
        data = stop_and_scan(
            truth,
            grid,
            num_poses=args.poses,
            beams=args.beams,
            max_range_cells=args.range_cells,
            sigma_cells=args.sigma,
            seed=int(rng.integers(2**31)),
        )
    except ValueError:  # no stop keeps the robot's clearance in this window: draw another
        return None
    x, pinned, unseen = scanned(grid, data.scans, args.sigma, kn)
    return Example(
        x=x,
        y=torch.from_numpy(truth.astype(np.float32)),
        scored=torch.from_numpy(kn & ~pinned),
        unseen=torch.from_numpy(unseen),
    )


@dataclass
class Plan:
    """A map to draw windows from: ``occupancy`` / ``known`` ``H x W`` bool, metres per cell."""

    occupancy: np.ndarray
    known: np.ndarray
    resolution: float | None


def generated_maps() -> dict[str, tuple]:
    """``training-set name -> (index, child seed)`` of the maps the ``generated`` tables counted
    (:func:`~ogm_ppl.datasets.mapgen.iter_corpus` with the tables' recorded seed, ``n``, shape, kinds, border)."""
    prov = json.loads((FITTED_DIR / "prior_generated.json").read_text())["provenance"]
    children = np.random.SeedSequence(int(prov["seed"])).spawn(int(prov["n"]))
    return {f"seedstream:{c.entropy}/{tuple(c.spawn_key)}": (i, c, prov) for i, c in enumerate(children)}


def load_map(corpus: str, name: str) -> Plan:
    """The training map ``name`` of ``corpus`` (a plan, or a generated map by its seed-stream name)."""
    if corpus == "generated":
        from ogm_ppl.datasets.mapgen import generate_map

        i, child, prov = generated_maps()[name]
        kinds = prov["kinds"]
        occ = generate_map(
            kinds[i % len(kinds)], tuple(prov["shape"]), np.random.default_rng(child), border=int(prov["border"])
        )
        return Plan(occ, np.ones_like(occ), 0.05)
    p = fp.load_plan(corpus, name)
    return Plan(p.occupancy, p.known, p.resolution)


def scene_examples(plan: Plan, window: int, crops: int, args, rng: np.random.Generator) -> list[Example]:
    """The whole map scanned along a planned route (the Table 6.4 simulator: ``--poses 0`` lets the route
    planner choose the stops), then ``crops`` random windows of its features with 200 known free cells."""
    from ogm_ppl.datasets.stop_and_scan import plan_route

    occ, known = plan.occupancy, plan.known
    grid = Grid(occ.shape, resolution=plan.resolution or 0.05)
    seed = int(rng.integers(2**31))
    plan_range = args.plan_range_cells or args.range_cells
    route = plan_route(occ, grid, num_poses=args.poses or None, max_range_cells=plan_range, seed=seed)
    if args.drive:
        scans = driven_scans(occ, grid, route, args, rng)
    else:
        scans = stop_and_scan(
            occ,
            grid,
            route=route,
            beams=args.beams,
            max_range_cells=args.range_cells,
            sigma_cells=args.sigma,
            seed=seed,
        ).scans
    x, pinned, unseen = scanned(grid, scans, args.sigma, known)
    H, W = occ.shape
    h, w = min(window, H), min(window, W)
    out = []
    for _ in range(4 * crops):
        if len(out) == crops:
            break
        r, c = int(rng.integers(0, H - h + 1)), int(rng.integers(0, W - w + 1))
        sl = (slice(r, r + h), slice(c, c + w))
        if (known[sl] & ~occ[sl]).sum() < 200:
            continue
        out.append(
            Example(
                x=x[:, sl[0], sl[1]].clone(),
                y=torch.from_numpy(occ[sl].astype(np.float32)),
                scored=torch.from_numpy(known[sl] & ~pinned[sl]),
                unseen=torch.from_numpy(unseen[sl]),
            )
        )
    return out


def driven_scans(occ: np.ndarray, grid: Grid, route: np.ndarray, args, rng: np.random.Generator) -> Scans:
    """Scans taken while driving ``route`` (:func:`~ogm_ppl.datasets.drive_route`): a pose every ``s`` cells
    of path, ``s`` drawn from ``--drive`` for each map, each scanning ``--fov`` degrees ahead with beams
    ``360 / --beams`` degrees apart and the simulator's range noise."""
    from ogm_ppl.datasets import drive_route, simulate_scans

    step = float(args.drive[int(rng.integers(len(args.drive)))])
    poses = drive_route(occ, grid, route, step_cells=step)
    n = max(1, round(args.beams * args.fov / 360))
    angles = np.arange(n) * (2 * np.pi / args.beams) - (n - 1) * np.pi / args.beams
    return simulate_scans(grid, occ, poses, angles, args.range_cells * grid.resolution, args.sigma, rng)


def build_set(corpus: str, names: list[str], n: int, window: int, args, seed: int, label: str) -> list[Example]:
    """``n`` windows of maps drawn from ``names``: each scanned on its own (:func:`make_example`), or with
    ``--scan-whole-map`` ``--crops`` windows a scene of the whole map (:func:`scene_examples`)."""
    rng = np.random.default_rng(seed)
    plans: dict[str, Plan] = {}
    out: list[Example] = []
    tries = 0
    t0 = time.perf_counter()
    while len(out) < n and tries < 4 * n:
        tries += 1
        name = names[int(rng.integers(len(names)))]
        if name not in plans:
            plans[name] = load_map(corpus, name)
        if args.scan_whole_map:
            new = scene_examples(plans[name], window, min(args.crops, n - len(out)), args, rng)
            plans.pop(name)  # whole maps are large and each is scanned afresh
        else:
            ex = make_example(plans[name], window, args, rng)
            new = [] if ex is None else [ex]
        before = len(out)
        out += new
        if len(out) // 100 > before // 100:
            print(f"  {label}: {len(out)}/{n} windows, {time.perf_counter() - t0:.0f} s", flush=True)
    if len(out) < n:
        raise SystemExit(f"{corpus}: only {len(out)} usable {label} windows of {n} after {tries} tries")
    return out


def _batch(exs: list[Example], sym: int) -> tuple[torch.Tensor, ...]:
    """Stack windows of one shape, turned by symmetry ``sym`` (0-7: ``sym % 4`` quarter turns, then a flip
    when ``sym >= 4``)."""

    def t(a: torch.Tensor) -> torch.Tensor:
        a = torch.rot90(a, sym % 4, dims=(-2, -1))
        return torch.flip(a, dims=(-1,)) if sym >= 4 else a

    return tuple(torch.stack([t(getattr(e, k)) for e in exs]) for k in ("x", "y", "scored", "unseen"))


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


def _share(n: int, k: int, i: int) -> int:
    """The ``i``-th of ``k`` near-equal parts of ``n``."""
    return n // k + (1 if i < n % k else 0)


# ------------------------------------------------------------------ checkpoints
#: settings a checkpoint must share with the run resuming it (the rest: where to write, how often to save)
_NOT_FINGERPRINTED = ("out", "fresh", "checkpoint_every")


def checkpoint_path(out: Path) -> Path:
    """Where the training of ``out`` keeps its checkpoint: ``out`` with ``.ckpt.npz``."""
    return out.with_name(out.stem + ".ckpt.npz")


def _settings(args) -> str:
    return json.dumps({k: v for k, v in sorted(vars(args).items()) if k not in _NOT_FINGERPRINTED}, default=str)


def save_checkpoint(path: Path, args, step: int, seconds: float, guide, opt, sched, rng, best, best_state, history):
    """Everything the loop carries after ``step`` (weights, Adam's moments, the schedule, both generators, the
    validation-best weights and the history), as plain arrays and JSON (never pickled), written atomically."""
    arrays: dict[str, np.ndarray] = {f"net.{k}": t.detach().numpy() for k, t in guide.net.state_dict().items()}
    if best_state is not None:
        arrays.update({f"best.{k}": t.numpy() for k, t in best_state.items()})
    osd = opt.state_dict()
    for i, st in osd["state"].items():
        for k, t in st.items():
            arrays[f"opt.{i}.{k}"] = torch.as_tensor(t).numpy()
    meta = {
        "format": 1,
        "step": step,
        "seconds": seconds,
        "settings": _settings(args),
        "param_groups": osd["param_groups"],
        "scheduler": sched.state_dict(),
        "rng": rng.bit_generator.state,
        "best": best,
        "history": history,
    }
    arrays["torch_rng"] = torch.get_rng_state().numpy()
    arrays["meta"] = np.array(json.dumps(meta, allow_nan=True))
    with atomic_write(path) as f:
        np.savez(f, **arrays)


def load_checkpoint(path: Path, args, guide, opt, sched, rng):
    """Restore what :func:`save_checkpoint` wrote into ``guide``, ``opt``, ``sched``, ``rng`` and torch's
    generator; returns ``(first step to run, seconds spent, best, best weights, history)``. A checkpoint of other
    settings, or one that cannot be read, is refused (``SystemExit`` naming the path)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in z.files if k != "meta"}
    except Exception as e:  # BadZipFile, OSError, ValueError, KeyError, JSONDecodeError
        why = f"{type(e).__name__}: {e}"
        raise SystemExit(f"{path}: not a readable checkpoint ({why}); delete it or pass --fresh") from None
    if meta.get("format") != 1:
        raise SystemExit(f"{path}: checkpoint format {meta.get('format')!r}, expected 1; delete it or pass --fresh")
    mine, theirs = json.loads(_settings(args)), json.loads(meta["settings"])
    differ = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
    if differ:
        raise SystemExit(
            f"{path}: checkpoint of another training (settings that differ: {', '.join(differ)}); "
            "rerun with its settings, or pass --fresh to start afresh"
        )
    try:
        guide.net.load_state_dict(
            {k[4:]: torch.from_numpy(v.copy()) for k, v in arrays.items() if k.startswith("net.")}
        )
        state: dict = {}
        for k, v in arrays.items():
            if k.startswith("opt."):
                _, i, name = k.split(".", 2)
                state.setdefault(int(i), {})[name] = torch.from_numpy(v.copy())
        opt.load_state_dict({"state": state, "param_groups": meta["param_groups"]})
        sched.load_state_dict(meta["scheduler"])
        rng.bit_generator.state = meta["rng"]
        torch.set_rng_state(torch.from_numpy(arrays["torch_rng"].copy()))
    except Exception as e:
        why = f"{type(e).__name__}: {e}"
        raise SystemExit(f"{path}: damaged checkpoint ({why}); delete it or pass --fresh") from None
    best_state = {k[5:]: torch.from_numpy(v.copy()) for k, v in arrays.items() if k.startswith("best.")} or None
    return int(meta["step"]) + 1, float(meta["seconds"]), meta["best"], best_state, meta["history"]


def train(args, stop_after: int | None = None) -> dict | None:
    """Train as the module docstring says; ``stop_after``: stop (as Ctrl-C does) after that many steps of this
    call, leaving the checkpoint (tests). Returns the artefact's record, or ``None`` when stopped."""
    torch.manual_seed(args.seed)
    corpora = list(args.corpus)
    name = GUIDE_JOIN.join(corpora)
    t0 = time.perf_counter()
    tr: list[Example] = []
    val: list[Example] = []
    records: dict[str, dict] = {}
    for i, corpus in enumerate(corpora):
        tr_names, val_names = split_plans(corpus)
        print(f"{corpus}: {len(tr_names)} training plans, {len(val_names)} validation plans", flush=True)
        seed = args.seed + 10 * i
        tr += build_set(corpus, tr_names, _share(args.examples, len(corpora), i), args.window, args, seed, "training")
        val += build_set(
            corpus, val_names, _share(args.val, len(corpora), i), args.window, args, seed + 1, "validation"
        )
        records[corpus] = {
            "training_plans": len(tr_names),
            "validation_plans": len(val_names),
            "plan_names_sha256": calibration.names_digest(tr_names + val_names),
            "tables_provenance": f"{FITTED_DIR.name}/prior_{corpus}.json",
        }
    t_data = time.perf_counter() - t0
    by_shape: dict[tuple, list[Example]] = {}
    for e in tr:
        by_shape.setdefault(tuple(e.y.shape), []).append(e)
    shapes = list(by_shape)
    weights = np.array([len(by_shape[s]) for s in shapes], float)
    guide = AmortisedGuide(
        channels=args.channels, dilations=tuple(args.dilations), phase=(0, 0), delta="p21", seed=args.seed
    )
    opt = torch.optim.Adam(guide.net.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=args.steps)
    rng = np.random.default_rng(args.seed + 2)
    best = {"bits_per_unseen_cell": math.inf}
    best_state = None
    history = []
    out = Path(args.out or FITTED_DIR / f"guide_{name}.npz")
    ckpt = checkpoint_path(out)
    first, spent = 1, 0.0
    if ckpt.exists() and not args.fresh:
        first, spent, best, best_state, history = load_checkpoint(ckpt, args, guide, opt, sched, rng)
        print(f"resuming from {ckpt} at step {first - 1}/{args.steps}", flush=True)
    stop = {"flag": False}

    def on_sigint(signum, frame):
        stop["flag"] = True

    old_handler = signal.signal(signal.SIGINT, on_sigint)
    t1 = time.perf_counter() - spent
    step = first - 1
    try:
        for step in range(first, args.steps + 1):
            s = shapes[int(rng.choice(len(shapes), p=weights / weights.sum()))]
            pool = by_shape[s]
            idx = rng.choice(len(pool), size=min(args.batch, len(pool)), replace=False)
            x, y, scored, _ = _batch([pool[i] for i in idx], int(rng.integers(8)))
            logit = guide.net(x)
            nll = torch.nn.functional.binary_cross_entropy_with_logits(logit, y, reduction="none")
            loss = (nll * scored).sum() / scored.sum().clamp(min=1)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            if step % args.eval_every == 0 or step == args.steps:
                v = losses(guide, val)
                v["step"] = step
                v["train_bits_per_cell"] = loss.item() / math.log(2)
                history.append(v)
                mark = ""
                if v["bits_per_unseen_cell"] < best["bits_per_unseen_cell"]:
                    best, mark = v, " *"
                    best_state = {k: t.detach().clone() for k, t in guide.net.state_dict().items()}
                print(
                    f"step {step}/{args.steps}: train {v['train_bits_per_cell']:.3f} bits/cell, validation "
                    f"{v['bits_per_cell']:.3f} bits/cell, {v['bits_per_unseen_cell']:.3f} bits/unseen cell{mark} "
                    f"({time.perf_counter() - t1:.0f} s)",
                    flush=True,
                )
            done = step == args.steps
            stopped = stop["flag"] or (stop_after is not None and step - first + 1 >= stop_after)
            if stopped or (not done and step % args.checkpoint_every == 0):
                spent = time.perf_counter() - t1
                save_checkpoint(ckpt, args, step, spent, guide, opt, sched, rng, best, best_state, history)
            if stopped and not done:
                print(
                    f"interrupted at step {step}/{args.steps}: checkpoint {ckpt}; the same command resumes", flush=True
                )
                return None
    finally:
        signal.signal(signal.SIGINT, old_handler)
    assert best_state is not None
    guide.net.load_state_dict(best_state)
    temperature = 1.0
    if args.temperature:
        temperature = fit_temperature(guide, val)
        after = losses(guide, val)
        print(
            f"temperature {temperature:.3f}: validation {best['bits_per_unseen_cell']:.3f} -> "
            f"{after['bits_per_unseen_cell']:.3f} bits/unseen cell",
            flush=True,
        )
        best = {**best, **after, "before_temperature": best["bits_per_unseen_cell"]}
    meta = {
        "kind": GUIDE_KIND,
        "corpus": name,
        **(records[name] if len(corpora) == 1 else {"corpora": records}),
        "scans": {
            "whole_map": bool(args.scan_whole_map),
            "poses": args.poses,
            "beams": args.beams,
            "range_cells": args.range_cells,
            "sigma_cells": args.sigma,
            "window": args.window,
            **({"drive_step_cells": list(args.drive), "fov_degrees": args.fov} if args.drive else {}),
            **({"plan_range_cells": args.plan_range_cells} if args.plan_range_cells else {}),
        },
        "training": {
            "objective": "E_{m ~ corpus, z ~ p(z|m)}[-mean_k log q(m_k|z)] over known unpinned cells",
            "examples": args.examples,
            "validation_examples": args.val,
            "steps": args.steps,
            "batch": args.batch,
            "lr": args.lr,
            "schedule": "cosine",
            "seed": args.seed,
            "kept_step": best["step"],
            "chosen_by": "validation bits per unseen near-mapped cell",
            "temperature": temperature,
        },
        "validation": {
            k: best[k]
            for k in ("bits_per_cell", "bits_per_unseen_cell", "unseen_cells", "before_temperature")
            if k in best
        },
        "seconds": {"data": round(t_data, 1), "training": round(time.perf_counter() - t1, 1)},
        "torch": torch.__version__,
    }
    guide.save(out, meta)
    side = out.with_suffix(".json")
    digest = hashlib.sha256(out.read_bytes()).hexdigest()
    atomic_write_text(side, json.dumps({"file": out.name, "sha256": digest, **meta, "history": history}, indent=1))
    ckpt.unlink(missing_ok=True)  # the artefact is written: the checkpoint is spent
    print(f"wrote {out} and {side}: kept step {best['step']}, {best['bits_per_unseen_cell']:.3f} bits/unseen cell")
    return meta


def main(argv=None, stop_after: int | None = None) -> dict | None:
    """The command line; ``stop_after``: see :func:`train`."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--corpus",
        required=True,
        nargs="+",
        choices=CORPORA,
        help="corpus, or several: one guide learned on all their training plans (windows shared evenly; named "
        "C1+C2, e.g. guide:houseexpo+ipa)",
    )
    ap.add_argument("--examples", type=int, default=600, help="training windows (default 600)")
    ap.add_argument("--val", type=int, default=60, help="validation windows (default 60)")
    ap.add_argument("--window", type=int, default=96)
    ap.add_argument("--poses", type=int, default=3, help="stops of a scan (0: the route planner's own number)")
    ap.add_argument(
        "--scan-whole-map",
        action="store_true",
        help="scan the whole map along a planned route, then crop --crops windows of it (Table 6.4's simulator)",
    )
    ap.add_argument(
        "--drive",
        type=float,
        nargs="+",
        default=None,
        metavar="CELLS",
        help="with --scan-whole-map: scan while driving the route, a pose every CELLS of path (one of the "
        "values drawn per map) instead of at the stops",
    )
    ap.add_argument("--fov", type=float, default=360.0, help="field of view of a driven scan, degrees ahead")
    ap.add_argument(
        "--plan-range-cells",
        type=float,
        default=None,
        help="with --scan-whole-map: the range the route planner assumes (default --range-cells); a stop must "
        "show 2 %% of its disc, so at a long range most house plans get a single stop",
    )
    ap.add_argument("--crops", type=int, default=8, help="windows a whole-map scene gives (--scan-whole-map)")
    ap.add_argument("--beams", type=int, default=90)
    ap.add_argument("--range-cells", type=float, default=75.0)
    ap.add_argument("--sigma", type=float, default=1.0)
    ap.add_argument("--channels", type=int, default=24)
    ap.add_argument("--dilations", type=int, nargs="+", default=[1, 2, 4, 8, 16, 1])
    ap.add_argument("--steps", type=int, default=2500)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--eval-every", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--no-temperature",
        dest="temperature",
        action="store_false",
        help="skip the temperature fitted on the validation windows' unseen cells",
    )
    ap.add_argument("--out", default=None, help="artefact path (.npz; default ogm_ppl/fitted/guide_CORPUS.npz)")
    ap.add_argument(
        "--checkpoint-every",
        type=int,
        default=100,
        help="steps between checkpoints (OUT.ckpt.npz; Ctrl-C also saves one; the same command resumes)",
    )
    ap.add_argument("--fresh", action="store_true", help="ignore a checkpoint and start afresh")
    args = ap.parse_args(argv)
    if len(set(args.corpus)) != len(args.corpus):
        raise SystemExit(f"--corpus names a corpus twice: {' '.join(args.corpus)}")
    if len(args.corpus) > min(args.examples, args.val):
        raise SystemExit("--examples and --val must give each corpus at least one window")
    if args.poses < 0 or (args.poses == 0 and not args.scan_whole_map):
        raise SystemExit("--poses must be at least 1 (0, the planner's own number, only with --scan-whole-map)")
    if args.drive is not None and (not args.scan_whole_map or not all(math.isfinite(s) and s > 0 for s in args.drive)):
        raise SystemExit("--drive needs --scan-whole-map and finite path steps above 0 cells")
    if not 0 < args.fov <= 360:
        raise SystemExit(f"--fov must lie in (0, 360] degrees, got {args.fov}")
    if args.plan_range_cells is not None and (
        not args.scan_whole_map or not (math.isfinite(args.plan_range_cells) and args.plan_range_cells > 0)
    ):
        raise SystemExit("--plan-range-cells needs --scan-whole-map and a finite range above 0 cells")
    if args.fov != 360 and args.drive is None:
        raise SystemExit("--fov applies to driven scans only (--drive); the stops scan 360 degrees")
    for k in (
        "examples",
        "val",
        "window",
        "beams",
        "channels",
        "steps",
        "batch",
        "eval_every",
        "crops",
        "checkpoint_every",
    ):
        if getattr(args, k) < 1:
            raise SystemExit(f"--{k.replace('_', '-')} must be at least 1")
    return train(args, stop_after)


if __name__ == "__main__":
    main()
