"""P(path free): the exact joint answer of an enumerable posterior against the product of its marginals
(:mod:`ogm_ppl.studies.path_free`)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.priors import prior_by_name
from ogm_ppl.studies.errors import StudyOptionError
from ogm_ppl.studies.path_free import (
    FILE_NAME,
    PathFreeSettings,
    _exact_answers,
    path_free,
    path_free_lines,
    straight_paths,
)


def test_straight_paths_are_every_run_of_a_row_or_column():
    paths = straight_paths(2, 3)
    # a row of 3 holds runs of length 2 (two) and 3 (one); a column of 2 one run of length 2
    assert len(paths) == 2 * 3 + 3 * 1
    assert [0, 1, 2] in [p.tolist() for p in paths] and [1, 4] in [p.tolist() for p in paths]
    assert all(len(p) >= 2 for p in paths)


def test_exact_answers_are_the_posteriors_own_prob_free():
    grid = Grid((3, 3), resolution=1.0)
    scans = Scans([[0.5, 0.5, 0.0]], [0.0, np.pi / 2], [[1.7, 2.2]], max_range=2.5)
    model = OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.5), prior_by_name("patch3:houseexpo", (3, 3)))
    post = brute_force(model)
    paths = straight_paths(3, 3)
    got = _exact_answers(post, np.asarray(model.latent), paths)
    want = [post.prob_free(torch.as_tensor(p)) for p in paths]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    # a path through the robot's own (pinned free) cell: that cell never counts against it
    assert got[0] == pytest.approx(post.prob_free(torch.tensor([1])), rel=1e-12)


def test_a_small_study_scores_both_answers_and_writes_its_file(tmp_path):
    s = PathFreeSettings(priors=("independent:houseexpo", "field2:houseexpo"), scenes=2, rows=3, cols=3, plans=2)
    doc = path_free(s, tmp_path, command="test", progress=False)
    assert json.loads((tmp_path / FILE_NAME).read_text())["summary"] == doc["summary"]
    assert len(doc["scenes"]) == 2
    for name in s.priors:
        r = doc["summary"][name]
        assert r["paths"] > 0 and 0 <= r["truth_free_share"] <= 1
        rows = [p for p in doc["paths"] if p["prior"] == name]
        # each answer is a probability; the product of marginals is what it says
        assert all(0 <= p["exact"] <= 1 + 1e-12 and 0 <= p["independent"] <= 1 for p in rows)
        assert sum(b["paths"] for b in doc["by_length"][name]) == r["paths"]
    assert len(path_free_lines(doc)) == 1 + len(s.priors)


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"rows": 5, "cols": 5}, "limit is 24"),
        ({"scenes": 0}, "scenes: must be"),
        ({"priors": ()}, "at least one prior"),
        ({"priors": ("nonsense",)}, "priors: 'nonsense'"),
        ({"sigma": 0.0}, "sigma: must lie in"),
    ],
)
def test_bad_settings_are_refused_before_any_work(kw, match, tmp_path):
    with pytest.raises(StudyOptionError, match=match):
        path_free(PathFreeSettings(**kw), tmp_path, progress=False)
    assert not (tmp_path / FILE_NAME).exists()
