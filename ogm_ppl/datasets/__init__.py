"""Data: the thesis's toy problems, simulation of range scans, and (later) real logs and floor plans."""

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
]
