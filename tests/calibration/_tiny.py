"""Tiny calibration settings shared by the tests of :mod:`ogm_ppl.calibration`."""

import numpy as np

from ogm_ppl.calibration import CalibrationSettings, TestMap, make_scene

#: two test corpora, one training corpus, three priors, one 36-cell map each, short chains
TINY = dict(
    test=("houseexpo", "generated"),
    train=("houseexpo",),
    priors=("independent", "mrf", "patch3"),
    plans=1,
    window=36,
    generated_shape=80,
    poses=2,
    beams=45,
    range_cells=30.0,
    sweeps=16,
    burn=4,
)


def tiny(**over) -> CalibrationSettings:
    return CalibrationSettings(**{**TINY, **over})


def box_scene(settings):
    """A 24 x 24 walled box with a wall half across, scanned with ``settings``."""
    truth = np.zeros((24, 24), dtype=bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    truth[12, :14] = True
    return make_scene(TestMap("generated", "box", "box", truth, np.ones_like(truth), 0.05), settings)
