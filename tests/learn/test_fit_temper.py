"""fit_temper: each kind's exponent is the grid's lowest mean validation NLL of the unseen cells, the scores equal
run_prior's on the same validation windows under tables counted on the same fit plans, the file reads back
through load_temper_params, refused options are named (one line from the command, exit 2) and nothing is
written outside the folder named."""

import json

import pytest
import torch

from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.learn import FitOptionError, TemperSettings, fit_temper
from ogm_ppl.learn.temper import VALIDATION_SEED, choose
from ogm_ppl.priors.named import load_temper_params
from tests.learn._helpers import files_under, fitted_dir_listing

TINY = TemperSettings(
    kinds=("mrf", "border_bo"), betas=(1.0, 0.5), plans=1, window=32, generated_shape=80, sweeps=4, burn=2, fit_limit=2
)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    root = tmp_path_factory.mktemp("temper")
    shipped = fitted_dir_listing()
    r = fit_temper(["dungeon", "generated"], root / "out", settings=TINY, progress=False)
    assert fitted_dir_listing() == shipped
    return root, r


def test_files_read_back_and_each_exponent_is_the_lowest_mean_nll(fitted):
    root, r = fitted
    assert files_under(root) == {"out/temper_dungeon.json", "out/temper_generated.json"}
    for corpus in ("dungeon", "generated"):
        p = load_temper_params(corpus, path=root / "out" / f"temper_{corpus}.json")
        assert p.beta == r.summary["beta"][corpus] and set(p.beta) == {"mrf", "border_bo"}
        for kind, v in p.validation.items():
            scores = dict(zip(v["betas"], v["mean_nll_bits"]))
            assert p.beta[kind] == min(scores, key=lambda b: (scores[b], -b))
    prov = load_temper_params("dungeon", path=root / "out" / "temper_dungeon.json").provenance
    assert prov["fit_names_sha256"] and prov["validation_plans_scored"] and prov["fit_plans"] == 2
    assert prov["command"].startswith("ogm-ppl fit-prior temper --corpus dungeon generated --out ")
    assert "--fit-limit 2" in prov["command"] and prov["fitted_by"] == "ogm_ppl.learn.fit_temper"


def test_scores_equal_run_prior_on_the_same_split(fitted):
    """The independent route: the dungeon split (every fifth training plan validation), tables of the first two
    fit plans, the first usable validation window; generated: a fresh generated map and the shipped tables."""
    root, _ = fitted
    from ogm_ppl.calibration import generated_windows, make_scene, run_prior, usable_windows
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.priors.learn import count_tables

    names = fp.training_plans("dungeon", limit=300)
    fit = [n for i, n in enumerate(names) if i % 5 != 4][:2]
    val = [n for i, n in enumerate(names) if i % 5 == 4]
    tables = count_tables(fp.iter_plans("dungeon", fit), symmetries=True, min_count_5x5=2, progress=False)
    cases = [
        ("dungeon", tables, usable_windows("dungeon", val, 1, 32)),
        ("generated", None, generated_windows(1, 80, 32, VALIDATION_SEED)),
    ]
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as the fit runs
    try:
        for corpus, t, maps in cases:
            doc = json.loads((root / "out" / f"temper_{corpus}.json").read_text())
            assert doc["provenance"]["validation_plans_scored"] == [m.name for m in maps]
            scene = make_scene(maps[0], TINY)
            for kind in TINY.kinds:
                v = doc["validation"][kind]
                for b, nll in zip(v["betas"], v["nll_bits"]):
                    name = f"{kind}:{corpus}" + ("" if b == 1.0 else f"@{b:g}")
                    want = run_prior(scene, name, TINY, tables=t)["scores"]["unseen"]["nll_bits"]
                    assert nll == [want], (corpus, kind, b)
    finally:
        torch.set_num_threads(threads)


def test_choose_prefers_the_larger_beta_on_ties():
    assert choose({1.0: [0.5, 0.7], 0.5: [0.6, 0.6], 0.25: [0.9]}) == 1.0


@pytest.mark.parametrize(
    ("kwargs", "option", "limit"),
    [
        ({"settings": TemperSettings(betas=(1.0, 1.5))}, "betas", "[0, 1]"),
        ({"settings": TemperSettings(kinds=("nope",))}, "kinds", "not a prior kind"),
        ({"settings": TemperSettings(plans=0)}, "plans", "between 1 and 1000"),
        ({"settings": TemperSettings(kernel="tempering")}, "kernel", "one of"),
        ({"corpus": "mars"}, "corpus", "generated, houseexpo"),
        ({"settings": TemperSettings(sample_seed=3)}, "sample_seed", "with --sample only"),
        ({"settings": TemperSettings(sample=1)}, "sample", "at least 2"),
        ({"settings": TemperSettings(sample=10), "corpus": "generated"}, "sample", "floor-plan corpora only"),
        ({"ship": True}, "out", "not both"),
    ],
)
def test_bad_options_are_named_and_nothing_is_written(tmp_path, kwargs, option, limit):
    kw = {"corpus": "dungeon", **kwargs}
    with pytest.raises(FitOptionError) as e:
        fit_temper(kw.pop("corpus"), tmp_path / "out", **kw)
    assert e.value.option == option and limit in str(e.value)
    assert not (tmp_path / "out").exists()


def test_the_fitted_folder_is_written_only_when_shipping(tmp_path):
    from ogm_ppl.priors.tables import FITTED_DIR

    with pytest.raises(FitOptionError, match="--ship"):
        fit_temper("dungeon", FITTED_DIR)


def test_an_update_of_a_file_of_other_settings_is_refused_before_it_runs(tmp_path):
    from ogm_ppl.priors.tables import FITTED_DIR

    doc = json.loads((FITTED_DIR / "temper_dungeon.json").read_text())
    (tmp_path / "temper_dungeon.json").write_text(json.dumps(doc))
    with pytest.raises(FitOptionError, match="other settings") as e:
        fit_temper("dungeon", tmp_path, settings=TINY, update=True)
    assert e.value.option == "update" and files_under(tmp_path) == {"temper_dungeon.json"}


def test_the_command_refuses_a_bad_option_in_one_line(tmp_path, capsys):
    argv = ["fit-prior", "temper", "--corpus", "dungeon", "--betas", "1", "2", "--out", str(tmp_path / "o")]
    assert ogm_ppl(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("ogm-ppl: error: --betas") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_quick_passes_its_settings_to_the_library(tmp_path, monkeypatch):
    """``fit-prior temper --quick``: two small plans, two betas and kinds, ten fit plans, the first corpus given
    (dungeon when all are); the script form defaults to every corpus and needs neither --out nor --ship."""
    import argparse

    import ogm_ppl.learn.temper as temper
    from ogm_ppl.cli._fit_kinds import add_temper, quick_temper
    from ogm_ppl.learn import FitResult
    from ogm_ppl.learn._fit_common import CORPORA

    calls = []
    monkeypatch.setattr(
        temper, "fit_temper", lambda *a, **kw: calls.append((a, kw)) or FitResult("temper", (), {}, {}, 0)
    )
    assert ogm_ppl(["fit-prior", "temper", "--quick", "--corpus", "ipa", "dungeon", "--out", str(tmp_path)]) == 0
    assert ogm_ppl(["fit-prior", "temper", "--corpus", "ipa", "--kinds", "border_bo", "--ship", "--quiet"]) == 0
    (args, kw), (args2, kw2) = calls
    s = kw["settings"]
    assert args == (["ipa"], tmp_path) and not kw["ship"] and not kw["update"]
    assert (s.plans, s.window, s.sweeps, s.burn, s.fit_limit) == (2, 48, 10, 4, 10)
    assert s.kinds == temper.KINDS[:2] and s.betas == temper.BETAS[:2]
    assert args2 == (["ipa"], None) and kw2["ship"] and kw2["settings"].kinds == ("border_bo",) and not kw2["progress"]
    ap = argparse.ArgumentParser()
    add_temper(ap, ship_by_default=True)
    a = ap.parse_args([])
    assert a.corpus == list(CORPORA) and a.out is None and not a.ship
    assert quick_temper(ap.parse_args(["--quick"])).corpus == ["dungeon"]


def test_a_sample_splits_the_random_plans_the_tables_were_counted_on(monkeypatch, tmp_path):
    """``--sample N --sample-seed S``: the fit and validation plans are every fifth of the random ``N`` training
    plans of ``fit-prior tables --sample N --sample-seed S`` (their natural order), recorded in the file's
    command and settings; the command passes them on."""
    import ogm_ppl.learn.temper as temper
    from ogm_ppl.learn import FitResult, load_training_plans
    from ogm_ppl.learn._heldout import split_names

    fit, val = split_names("schools", 10, 1)
    plans = load_training_plans("schools", sample=10, sample_seed=1).names
    assert (fit, val) == ([n for i, n in enumerate(plans) if i % 5 != 4], list(plans[4::5]))
    assert TemperSettings(sample=10, sample_seed=1).options() == ["--sample", "10", "--sample-seed", "1"]
    calls = []
    monkeypatch.setattr(
        temper, "fit_temper", lambda *a, **kw: calls.append(kw["settings"]) or FitResult("temper", (), {}, {}, 0)
    )
    argv = ["fit-prior", "temper", "--corpus", "schools", "--sample", "10", "--sample-seed", "1", "--quiet"]
    assert ogm_ppl([*argv, "--out", str(tmp_path)]) == 0
    assert (calls[0].sample, calls[0].sample_seed) == (10, 1)


def test_the_net_field_is_tempered_on_the_plans_its_fit_kept_for_validation(tmp_path):
    """A file kind (the shipped ``net:houseexpo``) counts no tables: its exponents are scored on windows of the
    plans its own fit kept for validation (every tenth training plan, none it trained on), and the record holds
    its prior samples' statistics at each exponent beside the validation plans'. A corpus without a net fit is
    refused before anything is written."""
    import numpy as np

    from ogm_ppl.learn._fit_common import load_training_plans
    from ogm_ppl.learn._heldout import file_kind_validation

    names = list(load_training_plans("houseexpo").names)
    own = file_kind_validation("net", "houseexpo")
    assert own == [n for i, n in enumerate(names) if i % 10 == 9]
    s = TemperSettings(kinds=("net",), betas=(1.0, 0.5), plans=1, window=32, sweeps=4, burn=2)
    r = fit_temper("houseexpo", tmp_path / "out", settings=s, progress=False)
    doc = json.loads(r.files[0].read_text())
    v = doc["validation"]["net"]
    assert {name.split("@")[0] for name in v["validation_plans_scored"]} <= set(own)
    assert doc["beta"]["net"] == choose(dict(zip(v["betas"], v["nll_bits"])))
    assert [row["beta"] for row in v["prior_samples"]] == [1.0, 0.5]
    for row in v["prior_samples"]:
        assert row["start_gap"] == row["occupied"]["occupied"] - row["free"]["occupied"]
    plan = v["validation_plan_statistics"]
    assert 0 < plan["occupied"] < 1 and np.isfinite(plan["occupied_run"]) and v["prior_sample_check"]["sweeps"] == 6
    assert load_temper_params("houseexpo", path=r.files[0]).beta == {"net": doc["beta"]["net"]}
    with pytest.raises(FitOptionError, match="no shipped net fit") as e:
        fit_temper("dungeon", tmp_path / "none", settings=s, progress=False)
    assert e.value.option == "kinds" and not (tmp_path / "none").exists()
