"""Prior names with a tempering suffix: ``KIND:CORPUS@BETA`` and ``@cal`` (the fitted exponent), and the
validation of the fitted exponent files."""

import json

import pytest

from ogm_ppl.priors import MRFPrior, TemperedPrior, prior_by_name
from ogm_ppl.priors.named import TEMPER_FORMAT, load_temper_params
from ogm_ppl.priors.tables import FITTED_DIR, available_tables

#: the shipped table sets with fitted tempering exponents (the thesis's corpora; the others have none yet)
TEMPERED = [c for c in available_tables() if (FITTED_DIR / f"temper_{c}.json").is_file()]


def test_explicit_exponent():
    p = prior_by_name("mrf:houseexpo@0.4", (8, 9))
    assert isinstance(p, TemperedPrior) and p.beta == 0.4 and isinstance(p.base, MRFPrior)
    assert p.num_cells == 72
    assert isinstance(prior_by_name("mrf:houseexpo@1", (8, 9)), MRFPrior)  # beta = 1: the prior itself


def test_the_thesis_corpora_have_fitted_exponents():
    assert {"generated", "houseexpo", "ipa", "dungeon"} <= set(TEMPERED)


@pytest.mark.parametrize("corpus", TEMPERED)
def test_calibrated_exponent_is_the_fitted_one(corpus):
    params = load_temper_params(corpus)
    assert params.corpus == corpus and params.beta
    for kind, beta in params.beta.items():
        p = prior_by_name(f"{kind}:{corpus}@cal", (12, 12))
        assert (p.beta if isinstance(p, TemperedPrior) else 1.0) == beta
        # the fit scored every exponent of its grid and kept the lowest mean validation NLL
        v = params.validation[kind]
        best = min(range(len(v["betas"])), key=lambda j: (v["mean_nll_bits"][j], -v["betas"][j]))
        assert v["betas"][best] == beta


def test_default_corpus_and_errors():
    assert prior_by_name("border_bo@cal", (12, 12)).num_cells == 144  # the default corpus's exponent
    with pytest.raises(ValueError, match="tempering exponent"):
        prior_by_name("mrf:houseexpo@hot", (4, 4))
    with pytest.raises(ValueError, match="finite and >= 0"):
        prior_by_name("mrf:houseexpo@-1", (4, 4))
    with pytest.raises(ValueError, match="no fitted tempering exponent for kind 'field'"):
        prior_by_name("field:houseexpo@cal", (16, 16))


def _write(path, **over):
    doc = {"format": TEMPER_FORMAT, "format_version": 1, "corpus": "x", "beta": {"mrf": 0.5}, "provenance": {}}
    doc.update(over)
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize(
    "over, match",
    [
        ({"format": "other"}, "format is not"),
        ({"format_version": 2}, "format_version"),
        ({"beta": [0.5]}, "'beta' must be an object"),
        ({"beta": {"mrf": 1.5}}, r"beta\['mrf'\] must be a number in \[0, 1\]"),
        ({"beta": {"mrf": True}}, "must be a number"),
        ({"provenance": 3}, "'provenance' must be an object"),
    ],
)
def test_malformed_file_is_refused_with_its_path(tmp_path, over, match):
    p = _write(tmp_path / "t.json", **over)
    with pytest.raises(ValueError, match=match) as e:
        load_temper_params("x", path=p)
    assert str(p) in str(e.value)


def test_broken_json_and_missing_file(tmp_path):
    p = tmp_path / "t.json"
    p.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_temper_params("x", path=p)
    with pytest.raises(FileNotFoundError, match="no fitted tempering exponents"):
        load_temper_params("nowhere")


def test_a_grid_of_other_cells_than_the_tables_were_counted_on_warns():
    """HouseExpo's tables were counted at 0.05 m a cell: a 0.1 m grid warns, a 0.05 m grid, a bare shape and a
    corpus that records no cell size (maps drawn in cells) do not."""
    import warnings

    from ogm_ppl import Grid
    from ogm_ppl.models.delta_setting import FittedSettingWarning

    with pytest.warns(FittedSettingWarning, match="learned on plans at 0.05 m a cell .* grid of 0.1 m a cell"):
        prior_by_name("patch3:houseexpo", Grid((12, 12), resolution=0.1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prior_by_name("patch3:houseexpo", Grid((12, 12), resolution=0.05))
        prior_by_name("patch3:houseexpo", (12, 12))
        prior_by_name("patch3:dungeon", Grid((12, 12), resolution=0.1))
        prior_by_name("independent", Grid((12, 12), resolution=0.1))
