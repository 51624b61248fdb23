"""ogm_ppl.studies.prior_stats: the statistics of each corpus's tables in a folder, beside the thesis's, written
only into the folder given; experiments/prior_stats.py reports the shipped tables."""

import json

from ogm_ppl.learn import fit_tables
from ogm_ppl.priors.tables import FITTED_DIR, load_tables
from ogm_ppl.studies.prior_stats import ROWS, THESIS, fit_corpus_tables, prior_stats, prior_stats_markdown
from tests._experiments import run_script
from tests._plan_folder import write_plan_folder


def test_the_statistics_are_the_tables_own(tmp_path):
    tables = tmp_path / "tables"
    fit_tables([write_plan_folder(tmp_path)], tables, pixel_size=0.025, name="ipa", progress=False)
    doc = prior_stats(tables, tmp_path / "report", timings={"ipa": 1.5})
    t = load_tables(tables / "prior_ipa.npz")
    lam, psi = t.mrf_fit(4)
    assert list(doc["corpora"]) == ["ipa"] and doc["thesis"] == THESIS and doc["timings"] == {"ipa": 1.5}
    assert doc["corpora"]["ipa"]["statistics"] == {**t.summary(), "mrf_lambda": lam, "mrf_psi": psi}
    assert sorted(p.name for p in (tmp_path / "report").iterdir()) == ["prior_stats.json", "prior_stats.md"]
    md = (tmp_path / "report" / "prior_stats.md").read_text()
    assert md == prior_stats_markdown(doc) + "\n" and "| statistic | thesis | ipa |" in md
    assert json.loads((tmp_path / "report" / "prior_stats.json").read_text()) == json.loads(json.dumps(doc))
    assert len([line for line in md.splitlines() if line.startswith("| ")]) == len(ROWS) + 2  # + header and MRF
    assert prior_stats(tmp_path / "nothing")["corpora"] == {}


def test_every_corpus_is_fitted_into_the_folder(tmp_path, monkeypatch):
    import ogm_ppl.learn

    calls = []
    monkeypatch.setattr(ogm_ppl.learn, "fit_tables", lambda c, out, limit, progress: calls.append((c, out, limit)))
    fits = fit_corpus_tables(tmp_path, {"generated": 4, "houseexpo": 3, "ipa": 3, "dungeon": 5}, progress=False)
    assert list(fits) == ["generated", "houseexpo", "ipa", "dungeon"]
    assert calls == [
        ("generated", tmp_path, 4),
        ("houseexpo", tmp_path, 3),
        ("ipa", tmp_path, 3),
        ("dungeon", tmp_path, 5),
    ]


def test_the_script_reports_the_shipped_tables(tmp_path):
    r = run_script("prior_stats.py", "--out", tmp_path / "ps")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "ps.json").read_text())
    assert list(doc["corpora"]) == ["generated", "houseexpo", "ipa", "dungeon"] and doc["timings"] is None
    assert r.stdout == (tmp_path / "ps.md").read_text()
    assert doc["corpora"] == json.loads(json.dumps(prior_stats(FITTED_DIR)["corpora"]))
