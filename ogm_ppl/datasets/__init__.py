"""Data: the thesis's toy problems, simulated range scans and stop-and-scan datasets, CARMEN logs, ROS bags, the
dataset file format, floor-plan corpora and generated ground-truth maps (training data for learned
priors, Section 6.1)."""

from ogm_ppl.datasets.carmen import CarmenFormatError, CarmenLog, read_carmen
from ogm_ppl.datasets.dataset_file import Dataset, DatasetFileError, load_dataset, save_dataset
from ogm_ppl.datasets.floorplans import (
    REAL_LOG_BUILDINGS,
    FloorPlan,
    heldout_plans,
    iter_plans,
    load_plan,
    training_plans,
)
from ogm_ppl.datasets.mapgen import generate_corpus, generate_map
from ogm_ppl.datasets.rosbag import read_bag
from ogm_ppl.datasets.simple2d import SimpleExample2D, simple_2d_example
from ogm_ppl.datasets.simulate import first_hit, simulate_scans
from ogm_ppl.datasets.stop_and_scan import StopAndScan, drive_route, plan_route, route_coverage, stop_and_scan
from ogm_ppl.datasets.toy1d import THESIS_TOY_READINGS, Toy1D, toy_1d
from ogm_ppl.datasets.walls1d import WallDatasets, wall_datasets

__all__ = [
    "REAL_LOG_BUILDINGS",
    "THESIS_TOY_READINGS",
    "CarmenFormatError",
    "CarmenLog",
    "Dataset",
    "DatasetFileError",
    "FloorPlan",
    "SimpleExample2D",
    "StopAndScan",
    "Toy1D",
    "WallDatasets",
    "drive_route",
    "first_hit",
    "generate_corpus",
    "generate_map",
    "heldout_plans",
    "iter_plans",
    "load_dataset",
    "load_plan",
    "plan_route",
    "read_bag",
    "read_carmen",
    "route_coverage",
    "save_dataset",
    "simple_2d_example",
    "simulate_scans",
    "stop_and_scan",
    "toy_1d",
    "training_plans",
    "wall_datasets",
]
