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
    with pytest.warns(FittedSettingWarning, match=r"or fit a net field on plan files read at 0\.1 m") as rec:
        prior_by_name("net:houseexpo", Grid((12, 12), resolution=0.1))  # a net field is fitted, not counted
    assert "count tables" not in str(rec[0].message)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prior_by_name("patch3:houseexpo", Grid((12, 12), resolution=0.05))
        prior_by_name("patch3:houseexpo", (12, 12))
        prior_by_name("patch3:dungeon", Grid((12, 12), resolution=0.1))
        prior_by_name("independent", Grid((12, 12), resolution=0.1))


# ------------------------------------------------------------------ net:CORPUS, the shipped net fields
def test_net_names_resolve_to_the_shipped_fit_learned_on_the_tables_plans():
    """``net:CORPUS`` is the shipped file's field (every parameter), whose JSON records the file's SHA-256 and was
    fitted on the very plans the corpus's tables were counted on (so the leakage checks built from the tables'
    provenance cover it)."""
    import hashlib

    import numpy as np

    from ogm_ppl.priors import NetFieldPrior
    from ogm_ppl.priors.named import net_corpora
    from ogm_ppl.priors.net_field import load_net_field, net_path

    assert "houseexpo" in net_corpora()
    for corpus in net_corpora():
        p = prior_by_name(f"net:{corpus}", (10, 12))
        d = load_net_field(net_path(corpus))
        assert isinstance(p, NetFieldPrior) and p.shape == (10, 12)
        for k in ("filters", "bias", "out"):
            assert np.array_equal(getattr(p, k), d[k])
        assert (p.unary, p.pad, p.activation, p.occupancy) == (d["unary"], d["pad"], d["activation"], d["occupancy"])
        side = json.loads(net_path(corpus).with_suffix(".json").read_text())
        assert side["sha256"] == hashlib.sha256(net_path(corpus).read_bytes()).hexdigest()
        tables = json.loads((FITTED_DIR / f"prior_{corpus}.json").read_text())["provenance"]
        assert side["provenance"]["plan_names_sha256"] == tables["plan_names_sha256"]
        assert side["provenance"]["excluded_buildings"] == tables["excluded_buildings"]
    assert isinstance(prior_by_name("net", (6, 6)), NetFieldPrior)  # the default corpus
    t = prior_by_name("net:houseexpo@0.5", (6, 6))
    assert isinstance(t, TemperedPrior) and t.beta == 0.5 and isinstance(t.base, NetFieldPrior)


def test_net_names_refuse_a_corpus_without_a_fit_tables_and_1d_grids():
    from ogm_ppl.priors.named import net_corpora
    from ogm_ppl.priors.tables import tables_by_name

    missing = next(c for c in available_tables() if c not in net_corpora())
    with pytest.raises(ValueError, match=f"no shipped net field for corpus '{missing}'.*shipped: .*houseexpo"):
        prior_by_name(f"net:{missing}", (8, 8))
    # a corpus with no tables either: the net fits shipped are listed, not the corpora with tables
    with pytest.raises(ValueError, match=r"no shipped net field for corpus 'nowhere'.*shipped: houseexpo"):
        prior_by_name("net:nowhere@0.5", (8, 8))
    with pytest.raises(ValueError, match="fitted net field, not count tables"):
        prior_by_name("net:houseexpo", (8, 8), tables=tables_by_name("houseexpo"))
    with pytest.raises(ValueError, match="2D patch prior"):
        prior_by_name("net:houseexpo", (8,))


def test_calibration_pairs_the_net_kind_with_its_fitted_corpora_only():
    from ogm_ppl.calibration import default_priors, prior_names
    from ogm_ppl.priors.named import net_corpora

    missing = next(c for c in available_tables() if c not in net_corpora())
    assert prior_names(["net", "field"], ["houseexpo", missing]) == [
        ("net:houseexpo", "houseexpo"),
        ("field:houseexpo", "houseexpo"),
        (f"field:{missing}", missing),
    ]
    with pytest.raises(ValueError, match=r"'net' is shipped for .*houseexpo"):
        prior_names(["net@0.5"], [missing])
    assert "net" in default_priors(["houseexpo"]) and "net" not in default_priors(["houseexpo", missing])
