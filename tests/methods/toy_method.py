"""A map method in one file, as a user would write it: registered on import (tests import it, and
``OGM_PPL_METHODS=tests.methods.toy_method`` makes the command line import it)."""

from dataclasses import dataclass

import numpy as np

from ogm_ppl.methods import Float, MapResult, param, register_method

NAME = "toy_endpoints"


@dataclass(frozen=True)
class EndpointParams:
    level: float = param(0.9, Float(0, 1), "occupancy given to the cells a beam ended in")


@register_method(NAME, EndpointParams)
def endpoints(params, problem, ctx):
    """Cells holding a beam's end point get ``level``, the other reached cells 0 (a toy)."""
    p = np.zeros(problem.grid.num_cells)
    p[problem.rays.endpoint_cells()] = params.level
    return MapResult(p, problem.rays.reached(), {"endpoint_cells": int((p > 0).sum())})
