"""fit_tables: the count tables of a corpus or of one's own plan files, written into the folder named only,
equal to counting the same plans with count_tables, read back by the table readers (load_tables,
prior_by_name), refused options named, and the fit-prior tables command."""

import json

import numpy as np
import pytest
import torch

from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.learn import FitOptionError, fit_tables
from ogm_ppl.priors import prior_by_name
from ogm_ppl.priors.learn import count_tables
from ogm_ppl.priors.tables import _ARRAYS, load_tables
from tests.learn._helpers import PIXEL_SIZE, files_under, fitted_dir_listing, plan_folder, read_plans


def _same_arrays(a, b) -> bool:
    return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in _ARRAYS) and a.truncated_mass == b.truncated_mass


def test_tables_of_own_plans_equal_counting_them_and_load_through_the_readers(tmp_path):
    plans = plan_folder(tmp_path)
    shipped = fitted_dir_listing()
    r = fit_tables(plans, tmp_path / "out", pixel_size=PIXEL_SIZE, progress=False)
    assert files_under(tmp_path / "out") == {"prior_plans.npz", "prior_plans.json"}
    assert files_under(tmp_path) == {f"out/{n}" for n in ("prior_plans.npz", "prior_plans.json")} | {
        f"plans/{n}" for n in files_under(plans)
    }
    assert fitted_dir_listing() == shipped
    # the independent route: the plans read one by one, counted as the shipped tables are counted
    direct = count_tables(read_plans(plans), symmetries=True, min_count_5x5=2, progress=False)
    tables = load_tables(r.files[0])
    assert _same_arrays(tables, direct)
    prov = tables.provenance
    assert (
        prov["command"].startswith("ogm-ppl fit-prior tables --plan-files ") and "--pixel-size 0.025" in prov["command"]
    )
    assert prov["corpus"] == "files" and prov["plans"] == 2 and prov["resolution"] == 0.05
    assert {"commit", "date", "machine", "plan_names_sha256", "sample"} <= set(prov)
    info = json.loads(r.files[1].read_text())
    assert info["file"] == "prior_plans.npz" and info["statistics"] == tables.summary()
    for kind in ("patch3", "border", "border1", "patch5", "mrf"):
        prior = prior_by_name(kind, (12, 12), tables=tables)
        assert np.isfinite(float(prior.log_prob(torch.zeros(144))))


def test_tables_of_a_corpus_record_it_and_load(tmp_path):
    r = fit_tables("generated", tmp_path, limit=1, progress=False)
    tables = load_tables(tmp_path / "prior_generated.npz")
    assert r.provenance["corpus"] == "generated" and r.provenance["n"] == 1 and r.provenance["resolution"] is None
    assert r.provenance["command"] == f"ogm-ppl fit-prior tables --corpus generated --limit 1 --out {tmp_path}"
    from ogm_ppl.datasets.mapgen import iter_corpus

    direct = count_tables(iter_corpus(1, (500, 500), seed=0), symmetries=True, min_count_5x5=2, progress=False)
    assert _same_arrays(tables, direct)
    assert np.isfinite(float(prior_by_name("border", (10, 10), tables=tables).log_prob(torch.zeros(100))))


@pytest.mark.parametrize(
    ("source", "kwargs", "option", "limit"),
    [
        ("generated", {"limit": 0}, "limit", "at least 1"),
        ("generated", {"min_count_5x5": 0}, "min_count_5x5", "at least 1"),
        ("generated", {"name": "../up"}, "name", "letters"),
        ("generated", {"pixel_size": 0.05}, "pixel_size", "plan files only"),
        ("nowhere", {}, "corpus", "generated, houseexpo, ipa, dungeon"),
        ("PLANS", {"pixel_size": -1.0}, "pixel_size", "(0, 1000]"),
        ("PLANS", {"pixel_size": PIXEL_SIZE, "resolution": 0}, "resolution", "(0, 10]"),
    ],
)
def test_bad_options_are_named_with_their_limit_and_nothing_is_written(tmp_path, source, kwargs, option, limit):
    src = plan_folder(tmp_path) if source == "PLANS" else source
    with pytest.raises(FitOptionError, match=option) as e:
        fit_tables(src, tmp_path / "out", progress=False, **kwargs)
    assert e.value.option == option and limit in str(e.value)
    assert not (tmp_path / "out").exists()


def test_an_out_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(FitOptionError, match=r"out: .* is a file"):
        fit_tables("generated", tmp_path / "f", limit=1, progress=False)


def test_the_command_fits_tables_and_refuses_a_bad_option(tmp_path, capsys):
    plans = plan_folder(tmp_path)
    out = tmp_path / "cmd"
    argv = ["fit-prior", "tables", "--plan-files", str(plans), "--pixel-size", "0.025", "--out", str(out), "--quiet"]
    assert ogm_ppl([*argv, "--name", "mine"]) == 0
    assert "prior_mine.npz" in capsys.readouterr().out
    direct = count_tables(read_plans(plans), symmetries=True, min_count_5x5=2, progress=False)
    assert _same_arrays(load_tables(out / "prior_mine.npz"), direct)
    assert ogm_ppl([*argv, "--min-count-5x5", "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ogm-ppl: error: --min-count-5x5") and len(err.strip().splitlines()) == 1


def test_the_fits_import_neither_the_experiments_nor_the_command_line_and_nothing_below_imports_them():
    from tests.inference.test_layering import PKG, _imports

    for path in sorted((PKG / "learn").rglob("*.py")):
        up = [m for m in _imports(path) if m.startswith(("ogm_ppl.experiment", "ogm_ppl.cli"))]
        assert not up, f"{path} imports {up}"
    for part in ("priors", "models", "inference", "datasets", "io.py", "provenance.py", "progress.py"):
        for path in sorted((PKG / part).rglob("*.py")) if not part.endswith(".py") else [PKG / part]:
            assert not [m for m in _imports(path) if m.startswith("ogm_ppl.learn")], f"{path} imports ogm_ppl.learn"


def test_a_random_sample_of_a_corpus_is_nested_recorded_and_refused_where_it_does_not_apply(tmp_path, monkeypatch):
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.learn import load_training_plans
    from ogm_ppl.learn._fit_common import sample_indices
    from tests.datasets._corpus_fixtures import write_houseexpo

    small, big = sample_indices(50, 5, 3), sample_indices(50, 20, 3)
    assert set(small) <= set(big) and small == sorted(small) and len(set(big)) == 20
    assert sample_indices(50, 5, 4) != small
    root = tmp_path / "corpora"
    write_houseexpo(root)
    monkeypatch.setenv("OGM_PPL_FLOORPLANS", str(root))
    train = fp.training_plans("houseexpo-full")
    plans = load_training_plans("houseexpo-full", sample=1, sample_seed=0)
    assert plans.names == (train[sample_indices(len(train), 1, 0)[0]],)
    assert plans.source["sample"] == {
        "random": 1,
        "seed": 0,
        "of": len(train),
        "rule": "sample_indices",
        "order": "natural",
    }
    r = fit_tables(plans, tmp_path / "out", progress=False)
    assert "--sample 1 --sample-seed 0" in r.provenance["command"] and r.provenance["plans"] == 1
    for source, kwargs in (("generated", {}), ("houseexpo-full", {"limit": 1})):
        with pytest.raises(FitOptionError, match="sample"):
            load_training_plans(source, sample=1, **kwargs)
    with pytest.raises(FitOptionError, match="at most"):
        load_training_plans("houseexpo-full", sample=len(train) + 1)
    argv = ["fit-prior", "tables", "--corpus", "houseexpo-full", "--sample", "1", "--out", str(tmp_path / "cmd")]
    assert ogm_ppl([*argv, "--quiet"]) == 0
    assert load_tables(tmp_path / "cmd" / "prior_houseexpo-full.npz").provenance["sample"]["random"] == 1
