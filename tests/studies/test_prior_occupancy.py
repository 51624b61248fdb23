"""ogm_ppl.studies.prior_occupancy (the study around ogm_ppl.learn.bias): each prior's share is its chains' own,
bad settings are refused naming them, only prior_occupancy.json (and bias.json when fitting) is written;
experiments/prior_occupancy.py prints the table."""

import json

import pytest

from ogm_ppl.learn import FitOptionError
from ogm_ppl.learn.bias import BiasSettings, occupancy_trace
from ogm_ppl.priors.tables import tables_by_name
from ogm_ppl.studies.errors import StudyOptionError
from ogm_ppl.studies.prior_occupancy import prior_occupancy, prior_occupancy_lines
from tests._experiments import run_script

TINY = BiasSettings(window=8, sweeps=4, every=2, bias_steps=1)


@pytest.mark.parametrize(
    "change, priors, match",
    [
        ({"window": 2}, ["patch3"], "window: must be between 4"),
        ({"sweeps": 10, "every": 6}, ["patch3"], "sweeps: must be between 12"),
        ({}, ["border_bo:dungeon"], "priors: takes kinds"),
    ],
)
def test_bad_settings_are_refused(tmp_path, change, priors, match):
    with pytest.raises(FitOptionError, match=match):
        prior_occupancy(priors, ["dungeon"], BiasSettings(**change), tmp_path, progress=False)
    with pytest.raises(StudyOptionError, match="out_dir"):
        prior_occupancy(["patch3"], ["dungeon"], TINY, fit_bias=True, progress=False)
    assert not any(tmp_path.iterdir())


def test_each_row_is_its_priors_chains_beside_its_corpus(tmp_path):
    doc = prior_occupancy(["patch3", "independent"], ["dungeon"], TINY, tmp_path, command="x", progress=False)
    assert [p.name for p in tmp_path.iterdir()] == ["prior_occupancy.json"]
    assert json.loads((tmp_path / "prior_occupancy.json").read_text()) == json.loads(json.dumps(doc))
    assert [r["prior"] for r in doc["rows"]] == ["patch3:dungeon", "independent:dungeon"]
    for r in doc["rows"]:
        chains = occupancy_trace(r["prior"], TINY)
        assert (r["share"], r["chain_shares"], r["traces"]) == (
            chains["share"],
            chains["chain_shares"],
            chains["traces"],
        )
        assert r["corpus_share"] == float(tables_by_name("dungeon").lam)
    assert doc["provenance"]["command"] == "x" and doc["settings"]["window"] == 8 and not doc["settings"]["fit_bias"]
    lines = prior_occupancy_lines(doc)
    assert lines[0] == "occupied share of an empty 8 x 8 window, second half of 3 chains"
    assert lines[2].startswith("patch3:dungeon") and len(lines) == 4


def test_the_biases_are_fitted_beside(tmp_path):
    doc = prior_occupancy(["patch3"], ["dungeon"], TINY, tmp_path, fit_bias=True, progress=False)
    fit = json.loads((tmp_path / "bias.json").read_text())["fits"]["patch3:dungeon"]
    assert doc["rows"][0]["fit"]["bias"] == fit["bias"] and doc["rows"][0]["fit"]["share"] == fit["share"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bias.json", "prior_occupancy.json"]
    assert prior_occupancy_lines(doc)[3].startswith("  biased, h = ")


def test_the_script_prints_the_table_and_refuses_a_bad_option(tmp_path):
    tiny = ["--priors", "patch3", "--train", "dungeon", "--window", "8", "--sweeps", "4", "--every", "2"]
    r = run_script("prior_occupancy.py", *tiny, "--out", tmp_path)
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "prior_occupancy.json").read_text())
    assert r.stdout.splitlines()[:3] == prior_occupancy_lines(doc)
    assert doc["provenance"]["command"].startswith("python experiments/prior_occupancy.py --priors patch3")
    bad = run_script("prior_occupancy.py", *tiny[:-2], "--every", "3", "--out", tmp_path / "x")
    assert bad.returncode == 2 and "error: sweeps: must be between 6" in bad.stderr and not (tmp_path / "x").exists()
