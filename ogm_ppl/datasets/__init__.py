"""Data: the thesis's toy problems, simulation of range scans, and (later) real logs and floor plans."""

from ogm_ppl.datasets.carmen import CarmenFormatError, CarmenLog, read_carmen
from ogm_ppl.datasets.dataset_file import Dataset, DatasetFileError, load_dataset, save_dataset
from ogm_ppl.datasets.simple2d import SimpleExample2D, simple_2d_example
from ogm_ppl.datasets.simulate import first_hit, simulate_scans
from ogm_ppl.datasets.toy1d import THESIS_TOY_READINGS, Toy1D, toy_1d
from ogm_ppl.datasets.walls1d import WallDatasets, wall_datasets

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
from ogm_ppl.datasets.floorplans import (
    REAL_LOG_BUILDINGS,
    FloorPlan,
    heldout_plans,
    iter_plans,
    load_plan,
    training_plans,
)
from ogm_ppl.datasets.mapgen import generate_corpus, generate_map

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
from ogm_ppl.datasets.stop_and_scan import StopAndScan, plan_route, route_coverage, stop_and_scan  # noqa: E402

__all__ += ["StopAndScan", "plan_route", "route_coverage", "stop_and_scan"]
