"""The 1D wall datasets of Section 2.5 (a stationary robot, a wall, Gaussian readings and the exact
posterior of each dataset): the training data of the Delta fit, defined beside it in
:mod:`ogm_ppl.inference.variational.wall_data` and re-exported here with the other datasets."""

from ogm_ppl.inference.variational.wall_data import WallDatasets, wall_datasets

__all__ = ["WallDatasets", "wall_datasets"]
