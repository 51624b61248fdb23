"""experiments/select_headline_prior.py on tiny settings, and the headline's reading of its output: the
shipped selection names a known prior, the spec uses it, and a damaged selection file is refused by name."""

import json
import sys

import pytest

from ogm_ppl.experiment.headline import HEADLINE_PRIOR_FORMAT, HeadlinePrior, headline_prior, headline_spec
from ogm_ppl.priors.named import prior_by_name
from tests._scripts import load_experiment


@pytest.fixture(scope="module")
def sel():
    mod = load_experiment("select_headline_prior", "select_headline_prior.py")
    yield mod
    for name in ("select_headline_prior", "calibration"):
        sys.modules.pop(name, None)


def test_quick_selection_writes_a_file_the_headline_reads(sel, tmp_path):
    out = tmp_path / "sel.json"
    doc = sel.main(["--quick", "--out", str(out)])
    got = headline_prior(out)
    assert (got.kind, got.corpus, got.update) == (doc["prior"], "houseexpo", doc["update"])
    # the winner has the best mean F1 of the candidates; OGM is scored beside them but never chosen
    cands = {k: v for k, v in doc["means"].items() if k != "ogm"}
    assert max(cands, key=lambda k: (cands[k]["best_f1"], cands[k]["auc"])) == f"{got.kind}/{got.update}"
    assert len(doc["rows"]) == 2 * (1 + len(cands))
    # the validation plans scored are not among the plans the selection's tables were counted on
    fit, val = sel.split_names("houseexpo")
    assert set(doc["provenance"]["validation_plans_scored"]) <= set(val)
    assert not set(val) & set(fit)


def test_shipped_selection_drives_the_headline_spec(tmp_path):
    p = headline_prior()
    assert prior_by_name(p.name, (12, 12)) is not None
    spec = headline_spec(tmp_path / "intel.log", quick=True, prior=p)
    learned = next(a for a in spec["algorithms"] if a["name"] == "learned-L9")
    assert (learned["prior"], learned["update"]) == (p.name, p.update)
    # the chosen prior beat traditional OGM on the validation plans it was chosen on
    assert p.means[f"{p.kind}/{p.update}"]["best_f1"] > p.means["ogm"]["best_f1"]


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
