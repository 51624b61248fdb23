"""select_headline_prior on tiny settings, and the headline's reading of its output: the winner is the candidate
of the best mean F1, each score equals a patch-Gibbs run of the same prior on the same validation window, the
shipped selection names a known prior and drives the spec, a damaged selection file is refused by name, refused
options are named (one line from the command, exit 2) and nothing is written outside the folder named."""

import json

import numpy as np
import pytest

from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.experiment.headline import (
    CHOSEN_BY,
    HEADLINE_PRIOR_FORMAT,
    HeadlinePrior,
    headline_prior,
    headline_spec,
)
from ogm_ppl.learn import FitOptionError, HeadlineSettings, select_headline_prior
from ogm_ppl.priors.named import prior_by_name
from tests.learn._helpers import files_under, fitted_dir_listing

TINY = HeadlineSettings(
    plans=1, window=48, sweeps=3, burn=1, candidates=(("patch3", "gibbs"), ("border", "thesis")), fit_limit=2
)


@pytest.fixture(scope="module")
def selected(tmp_path_factory):
    root = tmp_path_factory.mktemp("headline")
    shipped = fitted_dir_listing()
    r = select_headline_prior(root / "out", settings=TINY, progress=False)
    assert fitted_dir_listing() == shipped
    return root, r, json.loads(r.files[0].read_text())


def _split():
    from ogm_ppl.datasets import floorplans as fp

    names = fp.training_plans("houseexpo")
    return [n for i, n in enumerate(names) if i % 5 != 4], [n for i, n in enumerate(names) if i % 5 == 4]


def test_the_selection_is_a_file_the_headline_reads(selected):
    root, r, doc = selected
    assert files_under(root) == {"out/headline_prior.json"}
    got = headline_prior(r.files[0])
    assert (got.kind, got.corpus, got.update) == (doc["prior"], "houseexpo", doc["update"])
    # the winner has the best mean F1 of the candidates; OGM is scored beside them but never chosen
    cands = {k: v for k, v in doc["means"].items() if k != "ogm"}
    assert max(cands, key=lambda k: (cands[k]["best_f1"], cands[k]["auc"])) == f"{got.kind}/{got.update}"
    assert len(doc["rows"]) == TINY.plans * (1 + len(cands))
    # the validation plans scored are not among the plans the selection's tables were counted on
    fit, val = _split()
    assert set(doc["provenance"]["validation_plans_scored"]) <= set(val)
    assert not set(val) & set(fit)
    prov = doc["provenance"]
    assert prov["command"].startswith("ogm-ppl fit-prior headline --out ") and "--fit-limit 2" in prov["command"]
    assert prov["selected_by"] == "ogm_ppl.learn.select_headline_prior" and prov["fit_plans"] == 2


def test_scores_equal_patch_gibbs_on_the_same_window(selected):
    """The independent route: tables of the first two fit plans, the first usable validation window scanned as
    the calibration protocol scans it, each candidate's patch Gibbs and traditional OGM scored on its near cells."""
    _, _, doc = selected
    from ogm_ppl import GaussianRange, OccupancyModel
    from ogm_ppl.calibration import make_scene, usable_windows
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.inference import PatchGibbs, RunningStats, evidence_grid, run_gibbs
    from ogm_ppl.metrics import prediction_scores
    from ogm_ppl.models import delta_by_name
    from ogm_ppl.priors.learn import count_tables

    fit, val = _split()
    tables = count_tables(fp.iter_plans("houseexpo", fit[:2]), symmetries=True, min_count_5x5=2, progress=False)
    (t,) = usable_windows("houseexpo", val, 1, 48)
    sc = make_scene(t, TINY)
    rows = {r["candidate"]: r for r in doc["rows"] if r["plan"] == t.plan}

    def scores(q):
        s = prediction_scores(q, t.truth.ravel(), mask=sc.masks["near"])
        return {k: float(s[k]) for k in ("best_f1", "auc", "nll_bits")}

    ogm = evidence_grid(sc.rays, delta_by_name("haehnel")).probabilities.numpy()
    assert {k: rows["ogm"][k] for k in ("best_f1", "auc", "nll_bits")} == scores(ogm)
    for kind, update in TINY.candidates:
        prior = prior_by_name(f"{kind}:houseexpo", sc.grid.shape, tables=tables)
        model = OccupancyModel(sc.grid, sc.rays, GaussianRange(TINY.sigma), prior)
        stats = RunningStats(model)
        run_gibbs(
            PatchGibbs(model, (3, 3), update=update), TINY.sweeps, stats, warmup=TINY.burn, seed=0, progress=False
        )
        want = scores(np.clip(stats.marginals.numpy(), 0.0, 1.0))
        assert {k: rows[f"{kind}/{update}"][k] for k in want} == want, (kind, update)


def test_shipped_selection_drives_the_headline_spec(tmp_path):
    p = headline_prior()
    assert prior_by_name(p.name, (12, 12)) is not None
    spec = headline_spec(tmp_path / "intel.log", quick=True, prior=p)
    learned = next(a for a in spec["algorithms"] if a["name"] == "learned-L9")
    assert (learned["prior"], learned["update"]) == (p.name, p.update)
    # the chosen prior beat traditional OGM on the validation plans it was chosen on
    assert p.means[f"{p.kind}/{p.update}"]["best_f1"] > p.means["ogm"]["best_f1"]
    assert CHOSEN_BY == "ogm-ppl fit-prior headline"


def _doc(**kw) -> str:
    return json.dumps({"format": HEADLINE_PRIOR_FORMAT, "prior": "patch3", "corpus": "ipa", "update": "gibbs", **kw})


@pytest.mark.parametrize(
    "doc, what",
    [
        ("not json", "cannot read"),
        (json.dumps({"format": "other"}), "format"),
        (_doc(prior="nope"), "'prior'"),
        (_doc(corpus="mars"), "'corpus'"),
        (_doc(update="x"), "'update'"),
    ],
)
def test_damaged_selection_is_refused_naming_the_file(tmp_path, doc, what):
    f = tmp_path / "headline_prior.json"
    f.write_text(doc)
    with pytest.raises(ValueError, match=what) as e:
        headline_prior(f)
    assert str(f) in str(e.value)


def test_label_names_the_update():
    assert "thesis" in HeadlinePrior("border", "houseexpo", "thesis", {}).label
    assert HeadlinePrior("patch3_bo", "houseexpo", "gibbs", {}).name == "patch3_bo:houseexpo"


@pytest.mark.parametrize(
    ("kwargs", "option", "limit"),
    [
        ({"settings": HeadlineSettings(corpus="generated")}, "corpus", "houseexpo, ipa, dungeon"),
        ({"settings": HeadlineSettings(candidates=(("border", "x"),))}, "candidates", "gibbs, thesis"),
        ({"settings": HeadlineSettings(plans=0)}, "plans", "between 1 and 1000"),
        ({"settings": HeadlineSettings(sweeps=0)}, "sweeps", "between 1"),
        ({"name": "a/b"}, "name", "letters"),
        ({"ship": True}, "out", "not both"),
    ],
)
def test_bad_options_are_named_and_nothing_is_written(tmp_path, kwargs, option, limit):
    with pytest.raises(FitOptionError) as e:
        select_headline_prior(tmp_path / "out", **kwargs)
    assert e.value.option == option and limit in str(e.value)
    assert not (tmp_path / "out").exists()


def test_the_fitted_folder_is_written_only_when_shipping():
    from ogm_ppl.priors.tables import FITTED_DIR

    with pytest.raises(FitOptionError, match="--ship"):
        select_headline_prior(FITTED_DIR)


def test_the_command_refuses_a_bad_option_in_one_line(tmp_path, capsys):
    argv = ["fit-prior", "headline", "--candidates", "border", "--out", str(tmp_path / "o")]
    assert ogm_ppl(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("ogm-ppl: error: --candidates") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_quick_passes_its_settings_to_the_library(tmp_path, monkeypatch):
    """``fit-prior headline --quick``: two small plans, the first two candidates, ten fit plans; the script form
    needs neither --out nor --ship."""
    import argparse

    import ogm_ppl.learn.headline as headline
    from ogm_ppl.cli._fit_kinds import add_headline
    from ogm_ppl.learn import FitResult

    calls = []
    out = tmp_path / "sel.json"
    out.write_text("{}")

    def fake(*a, **kw):
        calls.append((a, kw))
        return FitResult("headline", (out,), {}, {}, 0)

    monkeypatch.setattr(headline, "select_headline_prior", fake)
    assert ogm_ppl(["fit-prior", "headline", "--quick", "--out", str(tmp_path), "--name", "sel"]) == 0
    assert ogm_ppl(["fit-prior", "headline", "--corpus", "ipa", "--ship", "--quiet"]) == 0
    (args, kw), (args2, kw2) = calls
    s = kw["settings"]
    assert args == (tmp_path,) and kw["name"] == "sel" and not kw["ship"]
    assert (s.plans, s.window, s.sweeps, s.burn, s.fit_limit) == (2, 64, 6, 2, 10)
    assert s.candidates == headline.CANDIDATES[:2]
    assert args2 == (None,) and kw2["ship"] and kw2["settings"].corpus == "ipa" and kw2["settings"].fit_limit is None
    ap = argparse.ArgumentParser()
    add_headline(ap, ship_by_default=True)
    a = ap.parse_args([])
    assert a.out is None and not a.ship and a.corpus == "houseexpo"
