"""``experiments/fit_temper.py --quick`` writes a file :func:`load_temper_params` accepts, whose exponent per
kind is the grid's lowest mean validation NLL."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))

import fit_temper

from ogm_ppl.priors.named import load_temper_params


def test_quick_fit_round_trips(tmp_path):
    (doc,) = fit_temper.main(["--quick", "--out", str(tmp_path)])
    p = load_temper_params("dungeon", path=tmp_path / "temper_dungeon.json")
    assert p.beta == doc["beta"] and set(p.beta) == {"mrf", "mrf8"}
    for kind, v in p.validation.items():
        scores = dict(zip(v["betas"], v["mean_nll_bits"]))
        assert p.beta[kind] == min(scores, key=lambda b: (scores[b], -b))
    assert doc["provenance"]["fit_names_sha256"] and doc["provenance"]["validation_plans_scored"]


def test_choose_prefers_the_larger_beta_on_ties():
    assert fit_temper.choose({1.0: [0.5, 0.7], 0.5: [0.6, 0.6], 0.25: [0.9]}) == 1.0
