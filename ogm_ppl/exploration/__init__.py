"""Exploration: where a robot should look next, from posterior samples of the map.

:mod:`ogm_ppl.exploration.information` computes the mutual information between the map and the readings
of candidate sensor poses (per beam exactly, per scan by nested Monte Carlo) and the independent-cell
baseline of FSMI / FCMI, and the expected number of not-yet-observed cells a candidate's scan would
observe (a coverage score over the samples), for any sensor with a compiled reading model
(:mod:`ogm_ppl.sensors_compiled`). Its work is split by job: :mod:`~ogm_ppl.exploration.rays` (the candidates'
beams), :mod:`~ogm_ppl.exploration.first_hits` (the samples as bit sets, the ray walks),
:mod:`~ogm_ppl.exploration.beam_mi` and :mod:`~ogm_ppl.exploration.scan_mi` (the compiled estimators).
"""

from ogm_ppl.exploration.information import (
    CandidateRays,
    ScanInformation,
    beam_information,
    candidate_rays,
    expected_new_cells,
    first_hit_distribution,
    independent_first_hits,
    independent_information,
    reading_distribution,
    scan_information,
)

__all__ = [
    "CandidateRays",
    "ScanInformation",
    "beam_information",
    "candidate_rays",
    "expected_new_cells",
    "first_hit_distribution",
    "independent_first_hits",
    "independent_information",
    "reading_distribution",
    "scan_information",
]
