r"""Priors and guides as predictors of what was not seen, and how well calibrated they are: the calibration
run (thesis Chapter 5, Sections 5.2.1-5.2.3), :func:`calibrate`.

The protocol. On held-out maps of each *test corpus* (:mod:`ogm_ppl.calibration.heldout`: ``generated`` maps
drawn from seeds disjoint from those the shipped ``generated`` tables counted; the held-out plans of
``houseexpo``, ``ipa`` and ``dungeon``, the buildings of the real logs left out) a ``window x window`` crop is
scanned sparsely (:func:`~ogm_ppl.calibration.scenes.make_scene`) and the posterior marginals
``q_k = p(m_k = 1 | z)`` are estimated with every prior learned on every *training corpus* (a test x train
matrix) by the chains of :mod:`ogm_ppl.calibration.chains`; traditional OGM with the fitted ``p21`` update is
the baseline row, and each corpus guide named (``guides``) adds a ``guide:C`` row, its one-pass marginals.
Every method is scored on the near-mapped cells ``N`` and their unseen cells ``U``: NLL in bits per cell
``-1/|M| sum_k log2 q_k^{m_k} (1 - q_k)^{1 - m_k}``, ECE and the reliability diagram (10 bins), Brier score,
ROC AUC, best F1 and IoU at 0.5, the seconds taken, and for a prior the share of unseen cells whose chains
agree (split R-hat < 1.05).

Leakage. A prior or guide is never scored on a map it was learned from: every (test set, training corpus)
pair is checked (:func:`~ogm_ppl.calibration.leakage.check_heldout`) before anything runs.

Outputs under ``out``: ``calibration.json`` (settings, provenance, one row per test set, map, method and mask,
with its reliability diagram; :mod:`ogm_ppl.calibration.results`), ``calibration_summary.json`` (the means over
maps without the diagrams: what the docs snapshot), ``calibration.md`` and the figures
(:mod:`ogm_ppl.calibration.report`). A rerun with the same settings skips the (map, method) pairs already in
the JSON and computes again those of a prior or guide that changed since.

Measured run times: the default run (2 maps per corpus, every shipped kind and its ``@cal`` beside it x every
shipped corpus, 673 rows, 16 skipped) took 53.5 min wall on 2 Intel Xeon cores that other jobs shared (load
average 2-3); without the ``@cal`` rows (512 rows) it took 23.5 min on 2 AMD EPYC cores under a load of 4-5.
``quick`` took 15 s once numba had compiled its kernels. Two runs of the default gave identical numbers.

>>> from ogm_ppl.calibration import CalibrationSettings, calibrate
>>> result = calibrate(CalibrationSettings(quick=True), Path("out/calibration"))  # doctest: +SKIP
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ogm_ppl._dtype import torch_threads
from ogm_ppl.calibration.chains import proposal_guide, run_guide, run_ogm, run_prior
from ogm_ppl.calibration.errors import PriorNameError, SettingsError
from ogm_ppl.calibration.heldout import TEST_CORPORA, TestMap, heldout_maps, plan_digests
from ogm_ppl.calibration.leakage import GUIDE_PREFIX, GUIDE_SYM, check_heldout, guide_for, guide_training_sets
from ogm_ppl.calibration.names import BIAS_SUFFIX, OGM_LABEL, OWN, load_bias_file, name_digest, prior_names
from ogm_ppl.calibration.report import figures, fmt, tables_md
from ogm_ppl.calibration.results import drop_changed, load_previous, row_key, rows_for, summary
from ogm_ppl.calibration.scenes import CalibrationScene, make_scene, plan_set_maps
from ogm_ppl.calibration.settings import CalibrationSettings, parse_patch_overrides
from ogm_ppl.io import atomic_write_text, writable_folder

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["CalibrationResult", "calibrate", "recorded_settings"]

#: the settings of one sampler only, recorded with the ``tempering`` kernel alone
_TEMPERING_KEYS = ("rungs", "beta_min", "temper")
#: the settings of the ``guided`` sampler only (recorded when it runs)
_GUIDED_KEYS = ("proposal_guide",)
#: settings not recorded: where the run writes and how, not what it computes
_UNRECORDED = ("fresh", "figures", "bias_file")


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` made: ``rows`` (one per test set, map, method and mask, as in
    ``calibration.json``), ``summary`` (the means over maps, with pooled reliability diagrams), ``skipped``
    (``{"test", "plan", "prior_name", "skipped": reason}`` per method skipped), ``path`` (the
    ``calibration.json`` written), ``settings`` (as recorded there) and ``figures`` (the PNGs written)."""

    rows: list[dict]
    summary: list[dict]
    skipped: list[dict]
    path: Path
    settings: dict
    figures: list[Path] = field(default_factory=list)


def recorded_settings(s: CalibrationSettings, bias: Mapping[str, float]) -> dict:
    """The settings ``calibration.json`` records for resolved settings ``s`` and the biases read from its bias
    file: every option but where and how the run writes (``fresh``, ``figures``) and the bias file's name (its
    biases instead, only when there are some), the tempering settings only with the ``tempering`` kernel,
    ``plans`` (maps per corpus) and ``plan_limit`` (maps of the plan set; ``None``: all), and with plan files
    their paths and :func:`~ogm_ppl.calibration.heldout.plan_digests` (a changed file refuses to resume).
    Sequences are lists, as read back from the JSON."""
    own = (() if s.kernel == "tempering" else _TEMPERING_KEYS) + (() if s.kernel == "guided" else _GUIDED_KEYS)
    order: tuple[str, ...] = (
        "test",
        "plan_files",
        "plan_set",
        "pixel_size",
        "plan_outside",
        "train",
        "priors",
        "guides",
    )
    order += ("guide_dir", "diagonal", "plans", "window", "generated_shape", "poses", "beams", "range_cells")
    order += ("sigma", "sweeps", "burn", "seed", "kernel", *_TEMPERING_KEYS, *_GUIDED_KEYS, "patch", "max_support")
    order += ("quick",)
    out: dict = {}
    for k in order:
        if k in own or k in _UNRECORDED:
            continue
        v = getattr(s, k)
        out[k] = list(v) if isinstance(v, tuple) else v
    out["plans"] = s.maps_per_corpus
    out["plan_limit"] = s.plans
    if bias:  # settings without biases read as those of runs made before biases existed
        out["bias"] = dict(bias)
    if s.plan_files:
        if not s.test:  # "plans" counts the corpora's maps; plan_limit the plan set's (None: all)
            del out["plans"]
        out["plan_files"] = [str(p) for p in s.plan_files]
        out["plan_digests"] = plan_digests(list(s.plan_files))
    else:  # likewise for runs made before plan files existed
        for k in ("plan_files", "plan_set", "pixel_size", "plan_outside", "plan_limit"):
            del out[k]
    return out


def _say(progress: bool, line: str) -> None:
    if progress:
        print(line, flush=True)


def calibrate(
    settings: CalibrationSettings, out: str | Path, *, progress: bool = True, command: str | None = None
) -> CalibrationResult:
    """Score every method of ``settings`` on every test map and write the results under ``out``, on one torch
    thread (a guide's float32 sums then do not depend on the machine's cores; the caller's count is restored).

    ``settings`` is resolved first (:meth:`~ogm_ppl.calibration.settings.CalibrationSettings.resolved`). Before
    any work: the bias file is read, every prior and guide built (:func:`~ogm_ppl.calibration.names.name_digest`)
    and the leakage of every (test set, training corpus) pair checked; ``out`` is created only after the names
    passed. Rows are computed map by map and ``calibration.json`` rewritten after each (a rerun with the same
    settings resumes; ``fresh`` starts over). With ``progress``, one line per row (and the tables at the end) is
    printed. ``command`` is recorded in the provenance block (:func:`ogm_ppl.provenance.provenance`; default
    this process's command line).

    Raises :class:`~ogm_ppl.calibration.errors.SettingsError` (a bad patch override, an output folder that
    cannot be written), :class:`~ogm_ppl.calibration.errors.PriorNameError`,
    :class:`~ogm_ppl.calibration.errors.BiasFileError`, :class:`~ogm_ppl.calibration.errors.ResultFileError`
    (or its :class:`~ogm_ppl.calibration.errors.SettingsMismatchError`),
    :class:`~ogm_ppl.calibration.leakage.GuideNameError`, :class:`~ogm_ppl.calibration.leakage.LeakageError`
    and :class:`~ogm_ppl.datasets.plan_files.PlanFileError`; all are ``ValueError``.
    """
    with torch_threads(1):
        return _calibrate(settings, out, progress=progress, command=command)


def _calibrate(
    settings: CalibrationSettings, out: str | Path, *, progress: bool, command: str | None
) -> CalibrationResult:
    """The work of :func:`calibrate` (its docstring), on the thread count the caller set."""
    from ogm_ppl.provenance import provenance

    s = settings.resolved()
    out = Path(out)
    path = out / "calibration.json"
    bias = load_bias_file(s.bias_file)
    recorded = recorded_settings(s, bias)
    overrides = parse_patch_overrides(s.patch)
    pairs = prior_names(s.priors or (), s.train or ())
    pairs += [(n + BIAS_SUFFIX, c) for n, c in pairs if n in bias]  # each biased prior beside its base
    guides = {c: guide_for(c, None if s.guide_dir is None else Path(s.guide_dir)) for c in s.guides or ()}
    pairs += [(GUIDE_PREFIX + c, c) for c in s.guides or ()]
    # each guide's training maps, per corpus it was learned on, as its record names them (checked on loading)
    guide_sets = {c: guide_training_sets(c.removesuffix(GUIDE_SYM), g.trained_for) for c, g in guides.items()}
    proposal_sets: dict[str, set[str]] = {}
    if s.kernel == "guided":  # the proposing guide is read before any work too (kept for the chains)
        try:
            g = proposal_guide(s.proposal_guide, s.guide_dir)
        except (ValueError, OSError) as e:
            raise SettingsError("proposal_guide", str(e)) from None
        proposal_sets = guide_training_sets(s.proposal_guide.removesuffix(GUIDE_SYM), g.trained_for)
    try:  # builds every prior once: an unknown name or unreadable tables stop the run before any work
        digests = {name: name_digest(name, bias, guides) for name, _ in [(OGM_LABEL, None), *pairs]}
    except (ValueError, LookupError, OSError) as e:
        raise PriorNameError(str(e.args[0]) if isinstance(e, KeyError) and e.args else str(e)) from None
    try:  # after the names: a refused run leaves no folder behind
        writable_folder(out)
    except OSError as e:
        raise SettingsError("out", str(e)) from None
    rows, runs = load_previous(path, recorded, s.fresh)
    rows = drop_changed(rows, digests, progress)
    done = {row_key(r) for r in rows}
    skipped: list[dict] = []
    skipped_keys: set[tuple] = set()
    prov = provenance(command)
    t_all = time.perf_counter()

    def save() -> None:
        doc = {
            "provenance": prov,
            "settings": recorded,
            "rows": rows,
            "skipped": skipped,
            "runs": [*runs, {"provenance": prov, "seconds": time.perf_counter() - t_all}],
            "seconds": sum(r["seconds"] for r in runs) + time.perf_counter() - t_all,
        }
        atomic_write_text(path, json.dumps(doc, indent=1))

    n_maps = s.maps_per_corpus
    test_sets: list[tuple[str, list[TestMap]]] = [
        (test, heldout_maps(test, n_maps, s.window, s.generated_shape)) for test in s.test or ()
    ]
    if s.plan_files:
        test_sets.append((s.plan_set, plan_set_maps(s, s.plans)))
    runs_of = {}
    for test, maps in test_sets:  # refuse leakage before anything runs
        own = test in TEST_CORPORA and s.diagonal  # a plan set has no priors of its own: every one runs on it
        runs_of[test] = [(n, c) for n, c in pairs if not own or n.startswith(GUIDE_PREFIX) or c in (None, OWN, test)]
        for name, train in runs_of[test]:
            if name.startswith(GUIDE_PREFIX):
                for c, train_set in guide_sets[name[len(GUIDE_PREFIX) :]].items():
                    check_heldout(test, [t.plan for t in maps], c, train_set)
            else:
                check_heldout(test, [t.plan for t in maps], train)
                for c, train_set in proposal_sets.items():  # the guided sampler's guide, as its record names it
                    check_heldout(test, [t.plan for t in maps], c, train_set)
    for test, maps in test_sets:
        _say(progress, f"[{test}] {len(maps)} held-out maps: " + ", ".join(f"{t.name} {t.truth.shape}" for t in maps))
        for t in maps:
            scene: CalibrationScene | None = None
            for name, train in [(OGM_LABEL, None), *runs_of[test]]:
                if (test, t.name, name) in done:
                    continue
                scene = scene or make_scene(t, s)
                if name == OGM_LABEL:
                    scores, secs = run_ogm(scene)
                    result: dict = {"scores": scores, "seconds": secs}
                elif name.startswith(GUIDE_PREFIX):
                    result = run_guide(scene, guides[name[len(GUIDE_PREFIX) :]], s.sigma)
                else:
                    result = run_prior(scene, name, s, overrides, bias=bias)
                    if "skipped" in result:
                        if (test, t.name, name) not in skipped_keys:
                            skipped.append({"test": test, "plan": t.name, "prior_name": name, **result})
                            skipped_keys.add((test, t.name, name))
                        _say(progress, f"  {test} {t.name[:28]}: {name:<22} skipped: {result['skipped']}")
                        continue
                rows += rows_for(test, t, name, train, s.kernel, result, digests[name])
                done.add((test, t.name, name))
                u = result["scores"]["unseen"]
                rh = f", rhat<1.05 {result['rhat_below']:.2f}" if "rhat_below" in result else ""
                _say(
                    progress,
                    f"  {test} {t.name[:28]}: {name:<22} NLL {u['nll_bits']:.3f} AUC {fmt(u['auc'])} "
                    f"ECE {u['ece']:.3f}{rh} ({result['seconds']:.1f} s, {time.perf_counter() - t_all:.0f} s in all)",
                )
                save()
    save()
    summ = summary(rows)
    brief = [{k: v for k, v in r.items() if k != "reliability"} for r in summ]
    atomic_write_text(
        out / "calibration_summary.json",
        json.dumps(
            {"provenance": prov, "settings": recorded, "summary": brief, "skipped": skipped}, separators=(",", ":")
        ),
    )
    md = tables_md(summ, recorded)
    atomic_write_text(out / "calibration.md", md)
    figs = figures(summ, out) if s.figures else []
    _say(progress, md)
    _say(progress, f"wrote {path}, {out / 'calibration.md'}" + (f" and {len(figs)} figures" if figs else ""))
    return CalibrationResult(rows=rows, summary=summ, skipped=skipped, path=path, settings=recorded, figures=figs)
