"""Data: the thesis's toy problems, simulation of range scans, and (later) real logs and floor plans."""

from .carmen import CarmenFormatError, CarmenLog, read_carmen
from .dataset_file import Dataset, DatasetFileError, load_dataset, save_dataset
from .simple2d import SimpleExample2D, simple_2d_example
from .simulate import first_hit, simulate_scans
from .toy1d import THESIS_TOY_READINGS, Toy1D, toy_1d
from .walls1d import WallDatasets, wall_datasets

__all__ = [
    "simulate_scans",
    "first_hit",
    "Toy1D",
    "toy_1d",
    "THESIS_TOY_READINGS",
    "SimpleExample2D",
    "simple_2d_example",
    "WallDatasets",
    "wall_datasets",
    "read_carmen",
    "CarmenLog",
    "CarmenFormatError",
    "save_dataset",
    "load_dataset",
    "Dataset",
    "DatasetFileError",
]

# Floor-plan corpora and generated ground-truth maps (training data for learned priors).
from .floorplans import (
    REAL_LOG_BUILDINGS,
    FloorPlan,
    heldout_plans,
    iter_plans,
    load_plan,
    training_plans,
)
from .mapgen import generate_corpus, generate_map

__all__ += [
    "FloorPlan",
    "REAL_LOG_BUILDINGS",
    "load_plan",
    "iter_plans",
    "training_plans",
    "heldout_plans",
    "generate_map",
    "generate_corpus",
]

# Simulated stop-and-scan datasets on any ground-truth map (Section 6.1).
from .stop_and_scan import StopAndScan, plan_route, route_coverage, stop_and_scan  # noqa: E402

__all__ += ["StopAndScan", "plan_route", "route_coverage", "stop_and_scan"]
