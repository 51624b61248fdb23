"""Shared by the tests of ogm_ppl.learn: the plans of write_plan_folder read as the fits read them, and the
files a fit may leave behind."""

from pathlib import Path

from tests._plan_folder import write_plan_folder

PIXEL_SIZE = 0.025  # write_plan_folder's PNG; its ROS map states its own 0.05 m


def plan_folder(tmp_path: Path) -> Path:
    return write_plan_folder(tmp_path)


def read_plans(folder: Path) -> list:
    """The plans of ``folder`` read directly (plan_files order, names as the fits name them)."""
    from ogm_ppl.datasets.plan_files import load_plan_file, plan_files, plan_names

    files = plan_files([folder])
    return [load_plan_file(f, pixel_size=PIXEL_SIZE, name=n) for f, n in zip(files, plan_names(files))]


def files_under(root: Path) -> set[str]:
    return {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()}


def fitted_dir_listing() -> dict[str, int]:
    """The shipped fitted files and their modification times (a fit must leave them alone)."""
    from ogm_ppl.priors.tables import FITTED_DIR

    return {p.name: p.stat().st_mtime_ns for p in FITTED_DIR.iterdir() if p.is_file()}
