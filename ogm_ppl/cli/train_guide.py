"""``ogm-ppl train-guide``: train a corpus guide for one's own sensor (:func:`~ogm_ppl.learn.train_corpus_guide`).

    ogm-ppl train-guide --corpus houseexpo --range-cells 400 --sigma 0.5 --out guides/guide_houseexpo.npz
    ogm-ppl train-guide --plan-files my_plans/ --pixel-size 0.05 --range-m 8 --out my_guide.npz
    ogm-ppl train-guide --corpus ipa --steps 20 --examples 16 --val 4 --out /tmp/g.npz        # a smoke run
    ogm-ppl train-guide --corpus houseexpo-full r2v schools ipa --sample 3000 --name real --ship
    ogm-ppl train-guide --corpus houseexpo-full --curve-sizes 60 600 6000 --validation-sample 300 --out out/gc

A command module of the ``ogm-ppl`` command line: :func:`add_parser` adds the subcommand, :func:`run` runs it
(exit status 0 when the guide is written, 130 when stopped by Ctrl-C with a checkpoint kept). Bad options raise
:class:`~ogm_ppl.learn.guide_settings.GuideSettingsError` (a ``ValueError``), which the command line prints as
one line ``ogm-ppl: error: ...`` (exit status 2).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ogm_ppl.learn.guide_settings import CORPORA, GuideTrainingSettings

__all__ = ["NAME", "add_arguments", "add_parser", "run", "settings_from_args", "shipped_path"]

NAME = "train-guide"

_DESCRIPTION = """\
Train the amortised guide q(m | z) on the training plans of floor-plan corpora (--corpus: the plans their
shipped tables counted, or with --sample N a random N of each one's training split), on plan files of
one's own (--plan-files: ROS map YAMLs, images, HouseExpo JSON) or both, scanned by the simulator with the
sensor given (range, noise, beams, stops or a driven route): the posterior predictive with those maps as the
prior. Every fifth plan of each source validates: it picks the step kept and fits a temperature. Checkpoints
into OUT.ckpt.npz every --checkpoint-every steps and on Ctrl-C; the same command resumes it bit for bit (a
checkpoint of other settings is refused; --fresh starts afresh). Writes OUT (.npz) and OUT.json (the record:
sources, sensor, training, validation losses, provenance)."""


def add_arguments(p: argparse.ArgumentParser, *, out_required: bool = True, curve: bool = True) -> None:
    """The options of the command (and of ``experiments/train_corpus_guide.py``, with ``out_required=False`` and
    without ``--curve-sizes``: ``curve=False``)."""
    d = GuideTrainingSettings(corpus=(CORPORA[0],))  # the defaults
    src = p.add_argument_group("maps")
    src.add_argument(
        "--corpus",
        nargs="+",
        choices=CORPORA,
        default=[],
        help="corpus, or several: one guide learned on all their tables' training plans (windows shared evenly; "
        "named C1+C2, e.g. guide:houseexpo+ipa, or --name)",
    )
    src.add_argument(
        "--sample",
        type=int,
        default=None,
        metavar="N",
        help="a random N of each corpus's training split instead of its tables' plans (all of a smaller one)",
    )
    src.add_argument("--sample-seed", type=int, default=0, help="the seed of --sample (0)")
    src.add_argument(
        "--validation-sample",
        type=int,
        default=None,
        metavar="M",
        help="validate on M plans of the training split fixed apart from --sample (the M after the first "
        "--validation-after of the --sample-seed permutation whose first N train) instead of every fifth sampled plan",
    )
    src.add_argument(
        "--validation-after",
        type=int,
        default=None,
        metavar="K",
        help="with --validation-sample: skip the first K plans of the permutation (default N; guides of every "
        "--sample up to K then share one validation set)",
    )
    if curve:
        src.add_argument(
            "--curve-sizes",
            type=int,
            nargs="+",
            default=None,
            metavar="N",
            help="the data curve: one guide per size N (the first N of the --sample-seed permutation of one "
            "--corpus), all validated on the --validation-sample plans after the largest; --out is then a folder: "
            "guide_C_N.npz each and data_curve_guide_C.json",
        )
    src.add_argument(
        "--name",
        default=None,
        help="the guide's name (guide:NAME; default the corpora joined, C1+C2); its record lists the corpora",
    )
    src.add_argument(
        "--plan-files",
        nargs="+",
        type=Path,
        default=[],
        metavar="PATH",
        help="plan files or folders of them (ROS map .yaml, .png/.pgm/.bmp images, HouseExpo .json) to train on, "
        "alone or with --corpus; every fifth plan validates",
    )
    src.add_argument("--pixel-size", type=float, default=None, help="metres per pixel of the plan images")
    sensor = p.add_argument_group("sensor and scans")
    sensor.add_argument("--poses", type=int, default=d.poses, help="stops of a scan (0: the route planner's number)")
    sensor.add_argument(
        "--scan-whole-map",
        action="store_true",
        help="scan the whole map along a planned route, then crop --crops windows of it (Table 6.4's simulator)",
    )
    sensor.add_argument(
        "--drive",
        type=float,
        nargs="+",
        default=None,
        metavar="CELLS",
        help="with --scan-whole-map: scan while driving the route, a pose every CELLS of path (one of the "
        "values drawn per map) instead of at the stops",
    )
    sensor.add_argument("--fov", type=float, default=d.fov, help="field of view of a driven scan, degrees ahead")
    sensor.add_argument(
        "--plan-range-cells",
        type=float,
        default=None,
        help="with --scan-whole-map: the range the route planner assumes (default the range); a stop must show "
        "2 %% of its disc, so at a long range most house plans get a single stop",
    )
    sensor.add_argument("--crops", type=int, default=d.crops, help="windows a whole-map scene gives (--scan-whole-map)")
    sensor.add_argument("--beams", type=int, default=d.beams, help=f"beams a full turn (default {d.beams})")
    rng = sensor.add_mutually_exclusive_group()
    rng.add_argument("--range-cells", type=float, default=d.range_cells, help="maximum range, cells (default 75)")
    rng.add_argument("--range-m", type=float, default=None, help="maximum range, metres (0.05 m a cell)")
    sensor.add_argument("--sigma", type=float, default=d.sigma, help="Gaussian range noise, cells (default 1)")
    train = p.add_argument_group("training")
    train.add_argument("--examples", type=int, default=d.examples, help=f"training windows (default {d.examples})")
    train.add_argument("--val", type=int, default=d.val, help=f"validation windows (default {d.val})")
    train.add_argument("--window", type=int, default=d.window, help=f"window side, cells (default {d.window})")
    train.add_argument("--channels", type=int, default=d.channels, help="channels of the network (default 24)")
    train.add_argument(
        "--dilations", type=int, nargs="+", default=list(d.dilations), help="layer dilations (default 1 2 4 8 16 1)"
    )
    train.add_argument("--steps", type=int, default=d.steps, help=f"Adam steps (default {d.steps})")
    train.add_argument("--batch", type=int, default=d.batch, help=f"windows a step (default {d.batch})")
    train.add_argument("--lr", type=float, default=d.lr, help="learning rate, cosine schedule (default 0.003)")
    train.add_argument("--eval-every", type=int, default=d.eval_every, help="steps between validations (default 100)")
    train.add_argument("--seed", type=int, default=d.seed, help="seed of the windows, scans and weights (default 0)")
    train.add_argument(
        "--no-temperature",
        dest="temperature",
        action="store_false",
        help="skip the temperature fitted on the validation windows' unseen cells",
    )
    outg = p.add_argument_group("output")
    where = outg.add_mutually_exclusive_group(required=out_required)
    where.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="FILE.npz",
        help="the guide file (and FILE.json); a folder with --curve-sizes",
    )
    where.add_argument(
        "--ship",
        action="store_true",
        help="maintainers: write ogm_ppl/fitted/guide_NAME.npz, the package's own guide (NAME: the corpora, C1+C2)",
    )
    outg.add_argument(
        "--checkpoint-every",
        type=int,
        default=d.checkpoint_every,
        help="steps between checkpoints (OUT.ckpt.npz; Ctrl-C also saves one; the same command resumes)",
    )
    outg.add_argument("--fresh", action="store_true", help="ignore a checkpoint and start afresh")
    outg.add_argument("--quiet", action="store_true", help="no progress lines")


def settings_from_args(args: argparse.Namespace) -> GuideTrainingSettings:
    """The settings the parsed options give (checked: :class:`GuideSettingsError` naming an option)."""
    return GuideTrainingSettings(
        corpus=tuple(args.corpus),
        plan_files=tuple(args.plan_files),
        pixel_size=args.pixel_size,
        sample=args.sample,
        sample_seed=args.sample_seed,
        validation_sample=args.validation_sample,
        validation_after=args.validation_after,
        name=args.name,
        examples=args.examples,
        val=args.val,
        window=args.window,
        poses=args.poses,
        scan_whole_map=args.scan_whole_map,
        drive=None if args.drive is None else tuple(args.drive),
        fov=args.fov,
        plan_range_cells=args.plan_range_cells,
        crops=args.crops,
        beams=args.beams,
        range_cells=args.range_cells,
        range_m=args.range_m,
        sigma=args.sigma,
        channels=args.channels,
        dilations=tuple(args.dilations),
        steps=args.steps,
        batch=args.batch,
        lr=args.lr,
        eval_every=args.eval_every,
        seed=args.seed,
        temperature=args.temperature,
        checkpoint_every=args.checkpoint_every,
    )


def shipped_path(settings: GuideTrainingSettings) -> Path:
    """Where ``--ship`` writes: the package's fitted guide of the settings' name (``guide_C1+C2.npz``,
    ``guide_NAME.npz``)."""
    from ogm_ppl.calibration.leakage import guide_path

    return guide_path(settings.label)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``train-guide`` to the subcommands ``sub`` of ``ogm-ppl``."""
    p = sub.add_parser(
        NAME,
        help="train a corpus guide for one's own sensor on corpora or plan files",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_arguments(p)


def run(args: argparse.Namespace) -> int:
    """Run ``ogm-ppl train-guide``: 0 when the guide is written, 130 when stopped with a checkpoint kept."""
    from ogm_ppl.learn.guide_training import train_corpus_guide

    if getattr(args, "curve_sizes", None) is not None:
        return _run_curve(args)
    settings = settings_from_args(args)
    out = shipped_path(settings) if args.ship else Path(args.out)
    if out.suffix != ".npz":
        raise ValueError(f"--out must name a .npz file, got {out}")
    r = train_corpus_guide(
        settings, out, progress=not args.quiet, fresh=args.fresh, command=settings.command(out, ship=args.ship)
    )
    if not r.finished:
        print(f"ogm-ppl train-guide: stopped at step {r.step}; checkpoint {r.checkpoint}: the same command resumes")
        return 130
    assert r.record is not None
    v = r.record["validation"]
    print(
        f"ogm-ppl train-guide: kept step {r.record['training']['kept_step']}, {v['bits_per_unseen_cell']:.3f} "
        f"bits/unseen cell (validation) -> {r.path} and {r.sidecar}"
    )
    return 0


def _run_curve(args: argparse.Namespace) -> int:
    """``--curve-sizes``: the guide's data curve (:func:`~ogm_ppl.learn.guide_curve.guide_data_curve`)."""
    from ogm_ppl.learn._fit_common import FitOptionError
    from ogm_ppl.learn.guide_curve import guide_data_curve
    from ogm_ppl.learn.guide_settings import GuideSettingsError

    def refuse(option: str, why: str) -> GuideSettingsError:
        return GuideSettingsError(option, f"--curve-sizes {why}")

    if len(args.corpus) != 1 or args.plan_files:
        raise refuse("corpus", "samples one corpus's training split: give one --corpus and no --plan-files")
    if args.sample is not None or args.validation_after is not None or args.name is not None:
        raise refuse("sample", "sets --sample, --validation-after and the guides' names itself: give none of them")
    if args.ship or args.out is None:
        raise refuse("out", "writes its guides and curve into the folder --out names (not --ship)")
    if args.validation_sample is None:
        raise refuse("validation_sample", "needs --validation-sample M: the validation plans every size shares")
    ns = argparse.Namespace(**{**vars(args), "validation_sample": None, "sample_seed": 0})
    try:
        r = guide_data_curve(
            args.corpus[0],
            args.out,
            sizes=args.curve_sizes,
            validation=args.validation_sample,
            seed=args.sample_seed,
            settings=settings_from_args(ns),
            progress=not args.quiet,
            fresh=args.fresh,
        )
    except FitOptionError as e:  # checked before any plan is read; named by its flag, as the other refusals are
        raise GuideSettingsError(e.option, f"--{e.option.replace('_', '-')}: {e.reason}") from None
    except KeyboardInterrupt as e:
        print(f"ogm-ppl train-guide: {e}")
        return 130
    for row in r.summary["rows"]:
        print(
            f"{row['plans']} plans: {row['validation_bits_per_unseen_cell_last']:.4f} bits/unseen cell at the last "
            f"step ({row['validation_bits_per_unseen_cell_tempered']:.4f} best and tempered)"
        )
    print(f"ogm-ppl train-guide: wrote {r.files[0]}")
    return 0
