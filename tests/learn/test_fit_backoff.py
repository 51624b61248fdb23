"""fit_backoff: the Witten-Bell weights of a corpus or of one's own plan files on a fit/validation split, equal
to fit_backoff_params on tables counted on the same split, read back by load_backoff_params and applied by
backed_off_prior, refused options named, nothing written outside the folder named, and the command."""

import json

import pytest

from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.learn import FitOptionError, fit_backoff
from ogm_ppl.priors.backoff import backed_off_prior, fit_backoff_params, load_backoff_params
from ogm_ppl.priors.learn import count_tables
from tests.learn._helpers import PIXEL_SIZE, files_under, fitted_dir_listing, plan_folder, read_plans

KAPPAS = ("kappa_patch3", "kappa_border", "kappa_border1")


def test_weights_of_own_plans_equal_the_library_fit_on_the_same_split_and_load(tmp_path):
    plans = plan_folder(tmp_path)
    shipped = fitted_dir_listing()
    r = fit_backoff(plans, tmp_path / "out", pixel_size=PIXEL_SIZE, validation_every=2)
    assert files_under(tmp_path / "out") == {"backoff_plans.json"}
    assert {p for p in files_under(tmp_path) if not p.startswith("plans/")} == {"out/backoff_plans.json"}
    assert fitted_dir_listing() == shipped
    # the independent route: plan 0 is the fit part, plan 1 (index % 2 == 1) validation
    fit_p, val_p = read_plans(plans)
    fit = count_tables([fit_p], symmetries=True, min_count_5x5=2, progress=False)
    val = count_tables([val_p], symmetries=True, min_count_5x5=1, progress=False)
    want = fit_backoff_params(fit, val, "plans")
    got = load_backoff_params("plans", path=r.files[0])
    assert all(getattr(got, k) == getattr(want, k) for k in KAPPAS)
    doc = json.loads(r.files[0].read_text())
    assert doc["validation"]["patch3_mean_log_lik"] == want.provenance["validation_mean_log_lik"]["patch3"]
    prov = got.provenance
    assert prov["command"].startswith("ogm-ppl fit-prior backoff --plan-files ")
    assert "--validation-every 2" in prov["command"]
    assert prov["fit_plans"] == 1 and prov["validation_plans"] == 1 and prov["corpus"] == "files"
    prior = backed_off_prior("border_bo", (12, 12), fit, params=got)
    assert prior.kappa == got.kappa_border


def test_weights_of_a_corpus_name_it_and_its_split(tmp_path):
    r = fit_backoff("generated", tmp_path, limit=3, validation_every=3)
    got = load_backoff_params("generated", path=tmp_path / "backoff_generated.json")
    assert got.corpus == "generated" and r.provenance["fit_plans"] == 2 and r.provenance["validation_plans"] == 1
    assert r.provenance["validation"] == "natural order, index % 3 == 2 -> validation"
    from ogm_ppl.datasets.mapgen import iter_corpus

    maps = list(iter_corpus(3, (500, 500), seed=0))
    fit = count_tables(maps[:2], symmetries=True, min_count_5x5=2, progress=False)
    val = count_tables(maps[2:], symmetries=True, min_count_5x5=1, progress=False)
    want = fit_backoff_params(fit, val)
    assert all(getattr(got, k) == getattr(want, k) for k in KAPPAS)


@pytest.mark.parametrize(
    ("kwargs", "option", "limit"),
    [
        ({"validation_every": 1}, "validation_every", "at least 2"),
        ({"validation_every": 3}, "validation_every", "at most 2"),
        ({"limit": -1}, "limit", "at least 1"),
        ({"name": ""}, "name", "letters"),
        ({"pixel_size": float("nan")}, "pixel_size", "(0, 1000]"),
    ],
)
def test_bad_options_are_named_with_their_limit_and_nothing_is_written(tmp_path, kwargs, option, limit):
    plans = plan_folder(tmp_path)
    with pytest.raises(FitOptionError) as e:
        fit_backoff(plans, tmp_path / "out", **{"pixel_size": PIXEL_SIZE, **kwargs})
    assert e.value.option == option and limit in str(e.value)
    assert not (tmp_path / "out").exists()


def test_the_command_fits_weights(tmp_path, capsys):
    plans = plan_folder(tmp_path)
    argv = ["fit-prior", "backoff", "--plan-files", str(plans), "--pixel-size", "0.025", "--out", str(tmp_path / "o")]
    assert ogm_ppl([*argv, "--validation-every", "2", "--quiet"]) == 0
    assert "backoff_plans.json" in capsys.readouterr().out
    assert load_backoff_params("plans", path=tmp_path / "o" / "backoff_plans.json").kappa_border > 0
    assert ogm_ppl(argv) == 2  # every fifth plan of two: none
    err = capsys.readouterr().err
    assert err.startswith("ogm-ppl: error: --validation-every") and len(err.strip().splitlines()) == 1
