r"""Anytime Gibbs runs: streamed statistics, checkpoints, resumption, thinned samples on disk.

:class:`RunningStats` accumulates, sweep by sweep, the running marginals ``p(m_k | z)``, ``p(f | z)`` of
chosen rays (Eq. 4.6), the joint occupancy and mutual information of chosen cell pairs, and the
probability that chosen paths are all free. It is also a ``hook_fn`` for ``pyro.infer.MCMC``, which
otherwise keeps every sample in memory.

:func:`run_gibbs` drives any of our kernels for ``num_sweeps`` sweeps with progress (a bar on a terminal, a
plain line every 10 s elsewhere once the run has taken 10 s: :class:`~ogm_ppl.progress.Progress`),
writes a checkpoint (map, torch RNG state, statistics; atomically) every ``checkpoint_every`` sweeps and
when interrupted (Ctrl-C stops at the end of the current sweep), and resumes from it: an interrupted and
resumed run gives bit for bit the result of an uninterrupted one with the same seed. A checkpoint carries
a fingerprint of the model, kernel and statistics (:mod:`ogm_ppl.inference.mcmc.fingerprint`); resuming it
with anything else is refused with a message naming what differs, and an unreadable checkpoint gives
one error naming the path.
"""

from __future__ import annotations

import os
import signal
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ogm_ppl._rng import keeps_global_rng
from ogm_ppl.exceptions import CheckpointError
from ogm_ppl.inference.mcmc.fingerprint import fingerprint
from ogm_ppl.io import atomic_write
from ogm_ppl.posterior import mutual_information_from_joint
from ogm_ppl.progress import Progress, progress_over

__all__ = ["CheckpointError", "GibbsRun", "RunningStats", "run_gibbs"]

_FORMAT = 4  # the kernel's entries follow MapKernel.state_dict (its own format: kernel_format)


class RunningStats:
    """Running statistics of map samples.

    Args:
        model: the :class:`~ogm_ppl.OccupancyModel`.
        rays: ray indices whose ``p(f | z)`` to track.
        pairs: ``P x 2`` cell pairs whose joint occupancy (and MI) to track.
        paths: lists of cells whose all-free probability to track.
        trace_cells: cells whose per-sweep values to keep (for R-hat / ESS); keep this small.
    """

    def __init__(self, model, rays=(), pairs=(), paths=(), trace_cells=()) -> None:
        self.model = model
        self.rays = torch.as_tensor(list(rays), dtype=torch.long)
        self.pairs = torch.as_tensor(np.asarray(pairs, dtype=np.int64).reshape(-1, 2))
        self.paths = [torch.as_tensor(list(p), dtype=torch.long) for p in paths]
        self.trace_cells = torch.as_tensor(list(trace_cells), dtype=torch.long)
        K = model.num_cells
        self.n = 0
        self._sum = np.zeros(K, np.float64)
        lengths = model.lengths[self.rays] if len(self.rays) else torch.zeros(0, dtype=torch.long)
        self._fh = [np.zeros(int(n) + 1, np.float64) for n in lengths]
        self._pair = np.zeros(len(self.pairs), np.float64)
        self._path = np.zeros(len(self.paths), np.float64)
        self._trace: list[np.ndarray] = []

    def update(self, m) -> None:
        """Add one sample: a full map (``K``, 0/1) or site ``"m"``'s latent cells (``L``)."""
        mt = self.model.full_map(torch.as_tensor(m))
        mn = mt.detach().cpu().numpy()
        self._sum += mn
        if len(self.rays):
            f = self.model.first_hits(mt.to(torch.float64), self.rays).numpy()
            for i, fi in enumerate(f):
                self._fh[i][fi] += 1
        if len(self.pairs):
            p = self.pairs.numpy()
            self._pair += mn[p[:, 0]] * mn[p[:, 1]]
        for i, path in enumerate(self.paths):
            self._path[i] += float(not mn[path.numpy()].any())
        if len(self.trace_cells):
            self._trace.append(mn[self.trace_cells.numpy()].astype(np.uint8))
        self.n += 1

    def __call__(self, kernel, params, stage, i) -> None:
        """``hook_fn`` for ``pyro.infer.MCMC``: accumulates samples after warm-up."""
        if stage.startswith("Sample"):
            self.update(params["m"])

    def _check(self):
        if self.n == 0:
            raise ValueError("no samples accumulated yet")

    @property
    def marginals(self) -> torch.Tensor:
        self._check()
        return torch.from_numpy(self._sum / self.n)

    def first_hit(self, i: int = 0) -> torch.Tensor:
        """``p(f | z)`` of the ``i``-th tracked ray (last entry: no occupied cell)."""
        self._check()
        return torch.from_numpy(self._fh[i] / self.n)

    def pair_joint(self) -> torch.Tensor:
        self._check()
        return torch.from_numpy(self._pair / self.n)

    def mutual_information(self) -> torch.Tensor:
        """MI of each tracked pair (``P``)."""
        self._check()
        p = self.marginals
        out = torch.empty(len(self.pairs), dtype=torch.float64)
        for j, (a, b) in enumerate(self.pairs.tolist()):
            p11 = torch.tensor([[p[a].item(), self._pair[j] / self.n], [self._pair[j] / self.n, p[b].item()]])
            out[j] = mutual_information_from_joint(torch.stack([p[a], p[b]]), p11)[0, 1]
        return out

    def prob_free(self) -> torch.Tensor:
        """All-free probability of each tracked path."""
        self._check()
        return torch.from_numpy(self._path / self.n)

    def trace(self) -> np.ndarray:
        """``sweeps x len(trace_cells)`` uint8 values of the traced cells."""
        return np.stack(self._trace) if self._trace else np.zeros((0, len(self.trace_cells)), np.uint8)

    def state_dict(self) -> dict:
        d = {"n": np.int64(self.n), "sum": self._sum, "pair": self._pair, "path": self._path, "trace": self.trace()}
        for i, a in enumerate(self._fh):
            d[f"fh{i}"] = a
        return d

    def load_state_dict(self, d) -> None:
        self.n = int(d["n"])
        self._sum = np.array(d["sum"], dtype=np.float64)
        self._pair = np.array(d["pair"], dtype=np.float64)
        self._path = np.array(d["path"], dtype=np.float64)
        tr = np.array(d["trace"])
        self._trace = list(tr) if tr.size else []
        self._fh = [np.array(d[f"fh{i}"], dtype=np.float64) for i in range(len(self._fh))]


@dataclass
class GibbsRun:
    """What :func:`run_gibbs` returns."""

    stats: RunningStats
    sweeps: int
    seconds: float
    interrupted: bool
    state: np.ndarray
    #: sampling seconds of the whole chain: the resumed checkpoint's (earlier calls) plus this call's
    seconds_total: float = 0.0


def _save_checkpoint(
    path: Path, kernel, stats: RunningStats, sweep: int, seed: int, warmup: int, fp: dict, seconds: float
) -> None:
    payload: dict[str, np.ndarray] = {f"kernel_{k}": np.asarray(v) for k, v in kernel.state_dict().items()}
    payload.update({f"stats_{k}": np.asarray(v) for k, v in stats.state_dict().items()})
    payload["rng"] = torch.get_rng_state().numpy()
    payload["sweep"] = np.asarray(sweep, np.int64)
    payload["seed"] = np.asarray(seed, np.int64)
    payload["warmup"] = np.asarray(warmup, np.int64)
    payload["format"] = np.asarray(_FORMAT, np.int64)
    payload["num_cells"] = np.asarray(kernel.model.num_cells, np.int64)
    payload["seconds"] = np.asarray(seconds, np.float64)  # the chain's sampling time up to ``sweep``
    for k, v in fp.items():
        payload[f"fp_{k}"] = np.asarray(v)
    with atomic_write(path) as f:
        np.savez(f, **payload)  # type: ignore[arg-type]  # numpy stub: **arrays could fill allow_pickle


_HINT = "delete it (or pass another checkpoint path) to start a fresh run"


#: what each fingerprint component (:mod:`~ogm_ppl.inference.mcmc.fingerprint`) covers, as a refusal names it
_COMPONENTS = {
    "grid": "the grid (shape, resolution, origin)",
    "readings": "the readings or the pinned cells",
    "sensor": "the likelihood table (the sensor model, or the prior's occupancy beyond the grid's edge)",
    "prior": "the prior",
    "kernel": "the kernel or its settings",
    "stats": "the tracked statistics",
}


def _load_checkpoint(
    path: Path, kernel, stats: RunningStats, seed: int, warmup: int, fp: dict, total: int
) -> tuple[int, float]:
    """Restore ``kernel``, ``stats`` and torch's generator; returns ``(sweep, seconds)`` of the checkpoint."""
    try:
        z = np.load(path, allow_pickle=False)
    except Exception as e:  # BadZipFile, OSError, ValueError (pickled or not an npz), EOFError
        raise CheckpointError(f"{path}: not a readable checkpoint ({type(e).__name__}: {e}); {_HINT}") from None
    with z:
        try:
            files = set(z.files)
            missing = [k for k in ("format", "num_cells", "seed", "sweep", "rng", "warmup") if k not in files]
            if missing:
                raise CheckpointError(f"{path}: not an ogm_ppl Gibbs checkpoint (no {', '.join(missing)}); {_HINT}")
            if int(z["format"]) != _FORMAT:
                raise CheckpointError(f"{path}: checkpoint format {int(z['format'])}, expected {_FORMAT}; {_HINT}")
            if int(z["num_cells"]) != kernel.model.num_cells:
                raise CheckpointError(
                    f"{path}: checkpoint of a map with {int(z['num_cells'])} cells, this model "
                    f"has {kernel.model.num_cells}; {_HINT}"
                )
            if int(z["seed"]) != seed:
                raise CheckpointError(f"{path}: checkpoint was written with seed {int(z['seed'])}, not {seed}; {_HINT}")
            if int(z["warmup"]) != warmup:
                raise CheckpointError(
                    f"{path}: checkpoint was written with warmup {int(z['warmup'])}, not {warmup} (the samples "
                    f"counted so far depend on it); {_HINT}"
                )
            differ = [k for k, v in fp.items() if f"fp_{k}" not in files or str(z[f"fp_{k}"]) != v]
            if differ:
                raise CheckpointError(
                    f"{path}: checkpoint belongs to another run; what differs from this run: "
                    f"{'; '.join(_COMPONENTS.get(k, k) for k in differ)}; {_HINT}"
                )
            if int(z["sweep"]) > total:
                raise CheckpointError(
                    f"{path}: checkpoint holds {int(z['sweep'])} sweeps (warm-up included), more than the {total} "
                    f"this run asks for; ask for at least as many, or {_HINT}"
                )
            _check_fields(path, z, stats)
            kernel.load_state_dict({k[7:]: z[k] for k in z.files if k.startswith("kernel_")})
            stats.load_state_dict({k[6:]: z[k] for k in z.files if k.startswith("stats_")})
            torch.set_rng_state(torch.from_numpy(z["rng"].copy()))
            seconds = float(z["seconds"]) if "seconds" in files else 0.0
            if not np.isfinite(seconds) or seconds < 0:
                raise CheckpointError(f"{path}: checkpoint's sampling time {seconds} is not a time; {_HINT}")
            return int(z["sweep"]), seconds
        except CheckpointError:
            raise
        except Exception as e:
            raise CheckpointError(f"{path}: damaged checkpoint ({type(e).__name__}: {e}); {_HINT}") from None


def _check_fields(path: Path, z, stats: RunningStats) -> None:
    """Refuse (:class:`CheckpointError` naming ``path`` and the field) a checkpoint whose sweep count or running
    statistics cannot come from a run: a negative sweep or sample count, a field of another shape than ``stats``
    keeps, a non-finite entry, a count outside ``[0, n]`` (``n`` samples: the sums of 0/1 values), a first-hit
    histogram not summing to ``n``, a traced value not 0 or 1, or not one traced row a sample."""

    def bad(field: str, why: str) -> CheckpointError:
        return CheckpointError(f"{path}: field {field} {why}: not a checkpoint a run writes; {_HINT}")

    for field in ("sweep", "stats_n"):
        if field not in z.files:
            raise bad(field, "is missing")
        v = z[field]
        if v.shape != () or v.dtype.kind not in "iu" or int(v) < 0:
            raise bad(field, f"is {v.tolist()!r}, not a count (a whole number >= 0)")
    n = int(z["stats_n"])
    own = stats.state_dict()
    for key, mine in own.items():
        field = f"stats_{key}"
        if key == "n":
            continue
        if field not in z.files:
            raise bad(field, "is missing")
        a = z[field]
        if key == "trace":
            if len(stats.trace_cells) and a.shape != (n, len(stats.trace_cells)):
                raise bad(
                    field,
                    f"has shape {a.shape}, not one row of {len(stats.trace_cells)} cells for each of the {n} samples",
                )
            if a.size and not np.isin(a, (0, 1)).all():
                raise bad(field, "holds a value other than 0 and 1")
            continue
        if a.shape != np.shape(mine):
            raise bad(field, f"has shape {a.shape}, this run's statistics {np.shape(mine)}")
        if a.dtype.kind not in "iuf":
            raise bad(field, f"holds {a.dtype} values, not counts")
        finite = np.isfinite(a)
        if not finite.all():
            i = int(np.flatnonzero(~finite.ravel())[0])
            raise bad(f"{field}[{i}]", f"is {a.ravel()[i]}: a running sum must be finite")
        out = (a < 0) | (a > n) | (a != np.round(a))
        if out.any():
            i = int(np.flatnonzero(out.ravel())[0])
            raise bad(f"{field}[{i}]", f"is {a.ravel()[i]}, outside the whole counts 0..{n} of its {n} samples")
        if key.startswith("fh") and a.sum() != n:
            raise bad(field, f"counts {a.sum():g} first hits, not one for each of the {n} samples")


@keeps_global_rng
def run_gibbs(
    kernel,
    num_sweeps: int,
    stats: RunningStats | None = None,
    warmup: int = 0,
    seed: int = 0,
    checkpoint: str | os.PathLike | None = None,
    checkpoint_every: int = 100,
    store_every: int = 0,
    store_dir: str | os.PathLike | None = None,
    progress: bool | Progress = True,
    stop_after: int | None = None,
) -> GibbsRun:
    """Run ``warmup + num_sweeps`` sweeps of ``kernel``; statistics count the last ``num_sweeps``.

    Args:
        kernel: a :class:`~ogm_ppl.inference.mcmc.kernel.MapKernel` (``CellGibbs``, ``PatchGibbs``,
            ``MetropolisCell``, ``GuidedGibbs``); the run uses its public protocol only (``setup``,
            ``current_params``, ``sample``, ``state``, ``state_dict`` / ``load_state_dict``).
        stats: where statistics accumulate (default: marginals only).
        seed: seeds torch's generator at the start of a fresh run (a resumed run restores its state); the
            caller's global random streams (torch, NumPy, ``random``) are as they were when the run returns.
        checkpoint: an ``.npz`` path; if it exists the run resumes from it (with the same ``seed``,
            ``warmup``, model, kernel and statistics, else :class:`CheckpointError`).
        store_every: keep every ``store_every``-th sample (bit-packed ``.npy``) in ``store_dir``.
        progress: show progress (:class:`~ogm_ppl.progress.Progress`); a caller that runs one chain in
            several calls passes its own ``Progress``, which each call updates and leaves open.
        stop_after: stop (as if interrupted) after this many sweeps of this call: for tests.
    """
    if num_sweeps < 0 or warmup < 0:
        raise ValueError("num_sweeps and warmup must be >= 0")
    stats = stats if stats is not None else RunningStats(kernel.model)
    ckpt = Path(checkpoint) if checkpoint is not None else None
    if ckpt is not None:
        if ckpt.suffix != ".npz":
            raise ValueError("checkpoint must be an .npz path")
        ckpt.parent.mkdir(parents=True, exist_ok=True)
    start, before = 0, 0.0
    fp = fingerprint(kernel, stats) if ckpt is not None else {}
    if ckpt is not None and ckpt.exists():
        start, before = _load_checkpoint(ckpt, kernel, stats, seed, warmup, fp, warmup + num_sweeps)
    else:
        torch.manual_seed(seed)  # before set-up: a drawn initial map ("prior") follows the seed too
        kernel.setup(warmup)
    if store_every and store_dir is None:
        raise ValueError("store_every needs store_dir")
    store = Path(store_dir) if store_dir is not None else None
    if store is not None:
        store.mkdir(parents=True, exist_ok=True)
    total = warmup + num_sweeps
    stop = {"flag": False}

    def handler(signum, frame):
        stop["flag"] = True

    old = signal.signal(signal.SIGINT, handler) if _main_thread() else None
    params = kernel.current_params()
    t0 = time.perf_counter()
    done = start
    try:
        with progress_over(progress, total, "gibbs sweeps", unit="sweep", initial=start) as bar:
            for i in range(start, total):
                params = kernel.sample(params)
                if i >= warmup:
                    stats.update(params[kernel.site])
                    if store is not None and store_every and (i - warmup) % store_every == 0:
                        with atomic_write(store / f"sweep_{i:09d}.npy") as f:
                            np.save(f, np.packbits(kernel.state))
                done = i + 1
                bar.update(1)
                if ckpt is not None and done % checkpoint_every == 0:
                    elapsed = before + time.perf_counter() - t0
                    _save_checkpoint(ckpt, kernel, stats, done, seed, warmup, fp, elapsed)
                if stop["flag"] or (stop_after is not None and done - start >= stop_after):
                    stop["flag"] = True
                    break
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
        seconds = time.perf_counter() - t0
        if ckpt is not None:
            _save_checkpoint(ckpt, kernel, stats, done, seed, warmup, fp, before + seconds)
    return GibbsRun(stats, done, seconds, bool(stop["flag"]) and done < total, kernel.state.copy(), before + seconds)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()
