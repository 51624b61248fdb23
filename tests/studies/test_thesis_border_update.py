"""ogm_ppl.studies.thesis_border_update: the thesis's border update leaves the tiled posterior by a visible gap,
the exact update by rounding only; experiments/thesis_border_update.py is its command line."""

import json

from ogm_ppl.studies.thesis_border_update import problems, thesis_border_update, thesis_border_update_lines
from tests._experiments import run_script


def test_the_thesis_update_misses_the_posterior_and_the_exact_one_does_not(tmp_path):
    doc = thesis_border_update([0], tmp_path, progress=False)
    assert [r["problem"] for r in doc["rows"]] == [name for name, _, _ in problems(0)]
    for r in doc["rows"]:
        assert r["thesis"]["total_variation"] > 1e-3 and r["thesis"]["max_abs_marginal_error"] > 1e-4
        assert r["gibbs"]["total_variation"] < 1e-9 and r["gibbs"]["max_abs_marginal_error"] < 1e-9
    assert doc["worst_thesis"]["total_variation"] == max(r["thesis"]["total_variation"] for r in doc["rows"])
    assert [p.name for p in tmp_path.iterdir()] == ["thesis_border_update.json"]
    assert json.loads((tmp_path / "thesis_border_update.json").read_text()) == doc
    lines = thesis_border_update_lines(doc)
    assert len(lines) == 3 and lines[-1].startswith("worst over 2 problems")


def test_the_script_has_its_options():
    r = run_script("thesis_border_update.py", "--help")
    assert r.returncode == 0 and "--out" in r.stdout, r.stderr
