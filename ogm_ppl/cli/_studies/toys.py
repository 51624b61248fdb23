"""The 1D studies and the update terms: ``table_3_1``, ``vi_vs_exact_1d``, ``vi_vs_mcmc``,
``thesis_border_update`` and ``fit_delta_setting`` (:mod:`ogm_ppl.cli._studies`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ogm_ppl.cli._studies import Study, StudyUsageError


# ------------------------------------------------------------------------------------------------ table_3_1
def _table_3_1_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--datasets", type=int, default=1000, help="random 1D datasets (1000)")
    ap.add_argument("--gibbs-sweeps", type=int, default=100_000, help="Gibbs sweeps per dataset, 0: no Gibbs row")
    ap.add_argument("--cells", type=int, default=30, help="latent cells K (30)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the datasets and chains (0)")
    ap.add_argument(
        "--out",
        type=Path,
        default=Path("out/experiments"),
        help="the folder of table_3_1.md and .json (out/experiments)",
    )


def _table_3_1_run(args: argparse.Namespace) -> dict:
    from ogm_ppl.studies.table_3_1 import Table31Settings, table_3_1, table_3_1_markdown

    res = table_3_1(Table31Settings(args.datasets, args.gibbs_sweeps, args.cells, args.seed), args.out)
    print(table_3_1_markdown(res))
    return res


TABLE_3_1 = Study(
    """The command line of :func:`ogm_ppl.studies.table_3_1.table_3_1` (the datasets, the rows and the score are in
:mod:`ogm_ppl.studies.table_3_1`): average summed KL between each mapping algorithm and the exact posterior on
random 1D datasets. Writes OUT/table_3_1.md and .json and prints the table.

    ogm-ppl study table_3_1 [--datasets 1000] [--gibbs-sweeps 100000] [--cells 30] [--seed 0]""",
    _table_3_1_arguments,
    _table_3_1_run,
)


# ------------------------------------------------------------------------------------------- vi_vs_exact_1d
def _vi_vs_exact_1d_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--quick", action="store_true", help="a fifth of the steps (smoke test)")
    ap.add_argument("--out", type=Path, default=Path("out/vi/vi_vs_exact_1d.md"), help="the Markdown file written")
    ap.add_argument("--seed", type=int, default=0, help="seed of the fits (0)")


def _vi_vs_exact_1d_run(args: argparse.Namespace) -> str:
    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.studies.vi_vs_exact_1d import vi_vs_exact_1d, vi_vs_exact_1d_markdown

    rows = vi_vs_exact_1d(args.quick, args.seed)
    text = vi_vs_exact_1d_markdown(rows, args.quick, args.seed)
    atomic_write_text(Path(args.out), text)
    print(text)
    return text


VI_VS_EXACT_1D = Study(
    """The command line of :func:`ogm_ppl.studies.vi_vs_exact_1d.vi_vs_exact_1d` (the problem, the guides and the
objectives are in :mod:`ogm_ppl.studies.vi_vs_exact_1d`): VI against the exact posterior on the thesis's 1D toy,
summed KL of marginals and wall-clock time. Writes --out (Markdown, atomically) and prints it.

    ogm-ppl study vi_vs_exact_1d [--quick]""",
    _vi_vs_exact_1d_arguments,
    _vi_vs_exact_1d_run,
)


# ----------------------------------------------------------------------------------------------- vi_vs_mcmc
def _vi_vs_mcmc_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--quick", action="store_true", help="small settings (under a minute)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the problems and the methods (0)")
    ap.add_argument(
        "--problems", default=None, help="comma-separated subset of toy,walls,2d:independent,2d:mrf8,2d:patch3"
    )
    ap.add_argument("--out", default="out/vi_vs_mcmc", help="the output folder (out/vi_vs_mcmc)")
    ap.add_argument("--replot", action="store_true", help="redraw table.md and the figure from results.json")


def _vi_vs_mcmc_run(args: argparse.Namespace) -> Any:
    from dataclasses import replace

    import torch

    from ogm_ppl.provenance import command_line
    from ogm_ppl.studies.vi_vs_mcmc import QUICK, ComparisonSettingsError, Settings, replot, run, write_results

    if args.replot:
        return replot(args.out)
    cfg = QUICK if args.quick else Settings()
    if args.problems:
        try:
            cfg = replace(cfg, problems=tuple(p.strip() for p in args.problems.split(",")))
        except ComparisonSettingsError as e:
            raise StudyUsageError(f"--problems: {e.reason}") from None
    torch.set_num_threads(1)
    try:
        import numba

        numba.set_num_threads(1)
    except (ImportError, ValueError):
        pass
    res = run(cfg, args.seed, log=lambda s: print(s, file=sys.stderr, flush=True))
    res["quick"] = bool(args.quick)
    res["command"] = command_line()
    print(write_results(res, args.out))
    return res


VI_VS_MCMC = Study(
    """One comparison harness: summed KL to the exact posterior against wall-clock time for every method, on the 1D
toy, on the 1000 wall datasets and on small 2D problems solved by brute force. The command line of
:func:`ogm_ppl.studies.vi_vs_mcmc.run` (the methods, problems and scores are described in
:mod:`ogm_ppl.studies.vi_vs_mcmc`). Times are wall clock on this machine (one thread), warm caches, excluding the
KL evaluation. Writes OUT/results.json, table.md and kl_vs_time.png.

    ogm-ppl study vi_vs_mcmc            # about 7 minutes on 2 shared cores
    ogm-ppl study vi_vs_mcmc --quick    # small settings, under a minute""",
    _vi_vs_mcmc_arguments,
    _vi_vs_mcmc_run,
)


# ------------------------------------------------------------------------------------- thesis_border_update
def _thesis_border_update_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--out", type=Path, default=Path("out"), help="the folder of thesis_border_update.json (out)")


def _thesis_border_update_run(args: argparse.Namespace) -> dict:
    from ogm_ppl.studies.thesis_border_update import FILE_NAME, thesis_border_update, thesis_border_update_lines

    doc = thesis_border_update(out_dir=args.out)
    print("\n".join(thesis_border_update_lines(doc)))
    print(f"-> {args.out / FILE_NAME}")
    return doc


THESIS_BORDER_UPDATE = Study(
    """The command line of :func:`ogm_ppl.studies.thesis_border_update.thesis_border_update` (the problems, the
exact one-sweep matrices and the gaps are in :mod:`ogm_ppl.studies.thesis_border_update`): how far the thesis's
border update (Section 5.2.3) is from the posterior it is meant to sample.

    ogm-ppl study thesis_border_update      # -> out/thesis_border_update.json (seconds after compiling)""",
    _thesis_border_update_arguments,
    _thesis_border_update_run,
)


# ---------------------------------------------------------------------------------------- fit_delta_setting
def _fit_delta_setting_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--sigma", type=float, required=True, help="sensor noise in cells")
    ap.add_argument("--F", type=int, required=True, help="max range in cells")
    ap.add_argument("--wall", type=int, default=None, help="wall cell (default round(0.8 F))")
    ap.add_argument("--num", type=int, default=1000, help="training datasets")
    ap.add_argument("--heldout", type=int, default=500, help="held-out datasets (seed + 1)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the training datasets (0)")
    ap.add_argument("--names", nargs="+", default=["p21", "moravec_opt"], help="the terms fitted")
    ap.add_argument("--out", default=None, help="folder for the fitted terms (reused when there)")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (small matrices: 1 is fastest)")
    ap.add_argument("--compare-full", action="store_true", help="also time the unreduced fit")


def _fit_delta_setting_run(args: argparse.Namespace) -> dict:
    import torch

    from ogm_ppl.studies.fit_delta_setting import delta_setting_heldout, delta_setting_lines

    torch.set_num_threads(args.threads)
    doc = delta_setting_heldout(
        args.sigma, args.F, wall=args.wall, num=args.num, heldout=args.heldout, seed=args.seed,
        names=args.names, out_dir=args.out, compare_full=args.compare_full,
    )  # fmt: skip
    print("\n".join(delta_setting_lines(doc)))
    return doc


FIT_DELTA_SETTING = Study(
    """Fit update terms Delta for one sensor setting (Section 2.5 at sigma, F in cells) and compare them with the
shipped ones (fitted at sigma 3, F 75, wall 60) on held-out data of that setting. The command line of
:func:`ogm_ppl.studies.fit_delta_setting.delta_setting_heldout` (the fit is
:func:`ogm_ppl.learn.fit_delta_setting`, ``ogm-ppl fit-prior delta-setting``).

    ogm-ppl study fit_delta_setting --sigma 1 --F 400 [--out DIR] [--names p21 moravec_opt]

Intel at 5 cm: F = 20 m / 0.05 m = 400 cells; sigma in cells = sigma_m / 0.05. Prints, per term: data and fit
seconds, train and held-out cross-entropy (mean over datasets of the summed cell cross-entropy, nats) of the fit
and of the shipped term on the same held-out data. --out: write (or reuse) the fitted terms there.
--compare-full: also time the fit without the near-wall reduction.""",
    _fit_delta_setting_arguments,
    _fit_delta_setting_run,
)

STUDIES = {
    "table_3_1": TABLE_3_1,
    "vi_vs_exact_1d": VI_VS_EXACT_1D,
    "vi_vs_mcmc": VI_VS_MCMC,
    "thesis_border_update": THESIS_BORDER_UPDATE,
    "fit_delta_setting": FIT_DELTA_SETTING,
}
