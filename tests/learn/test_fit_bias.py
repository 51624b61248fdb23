"""fit_bias and the occupancy chains it bisects on: a prior's own occupied share on a window with no readings.
Under the learned independent prior every recorded state is an exact draw (each sweep redraws every cell from
``lambda``), so its mean share lies within 4 standard errors of the corpus's ``lambda`` and its fitted bias is
near 0; each bisection step's share equals the chains run again at that ``h``; the file reads back through
load_bias_file; refused options are named (one line from the command, exit 2) and nothing is written outside
the folder named."""

import json
import math

import pytest

from ogm_ppl.calibration import load_bias_file
from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.learn import BiasSettings, FitOptionError, fit_bias
from ogm_ppl.learn.bias import empty_model, occupancy_trace
from ogm_ppl.priors.named import prior_by_name
from ogm_ppl.priors.tables import tables_by_name
from tests.learn._helpers import files_under, fitted_dir_listing


def test_the_independent_prior_fills_its_lambda():
    s = BiasSettings(window=20, sweeps=40, every=2)
    r = occupancy_trace("independent:dungeon", s)
    assert [len(t) for t in r["traces"]] == [20, 20, 20]
    lam = float(tables_by_name("dungeon").lam)
    _, counted = empty_model(prior_by_name("independent:dungeon", (20, 20)), 20)
    K, n = int(counted.sum()), 3 * 10  # counted cells; recorded states in the chains' second halves
    assert 0 < K < 400
    assert abs(r["share"] - lam) < 4 * math.sqrt(lam * (1 - lam) / (K * n))


def test_a_tile_prior_runs_from_every_start():
    r = occupancy_trace("border_bo:houseexpo", BiasSettings(window=12, sweeps=4, every=2))
    assert r["patch"] == [3, 3] and len(r["chain_shares"]) == 3
    assert r["traces"][1][0] > r["traces"][0][0]  # the all-occupied start is still fuller after 2 sweeps


def test_the_fitted_bias_of_the_independent_prior_is_near_zero(tmp_path):
    """The learned independent prior already fills its corpus's share, so the fitted bias is 0 up to the bisection's
    resolution (4 / 2^8 = 0.016) and the noise of 20 recorded states of ~390 cells (a share's standard error of
    0.0055, 0.023 in ``h`` at a slope ``lambda (1 - lambda) = 0.235``): within 0.1. ``bias.json`` holds it by name."""
    shipped = fitted_dir_listing()
    s = BiasSettings(window=20, sweeps=40, every=4)
    r = fit_bias(["independent"], tmp_path / "out", train=["dungeon"], settings=s, progress=False)
    assert files_under(tmp_path) == {"out/bias.json"} and fitted_dir_listing() == shipped
    doc = json.loads(r.files[0].read_text())
    fit = doc["fits"]["independent:dungeon"]
    assert abs(fit["bias"]) < 0.1 and len(fit["steps"]) == 7
    lam = fit["corpus_share"]
    assert lam == float(tables_by_name("dungeon").lam)
    assert [h for h, _ in fit["steps"]][:2] == [0.0, 1.0 if fit["steps"][0][1] < lam else -1.0]
    assert load_bias_file(r.files[0]) == {"independent:dungeon": fit["bias"]} == r.summary["bias"]
    assert doc["format"] == "ogm_ppl.prior_bias"
    prov = doc["provenance"]
    assert prov["command"].startswith("ogm-ppl fit-prior bias --priors independent --train dungeon --out ")
    assert "--window 20" in prov["command"] and prov["fitted_by"] == "ogm_ppl.learn.fit_bias"
    # the lower-level computation: each step's share is the two-chain share at its h, bisected towards lambda
    lo, hi = -s.bias_range, s.bias_range
    for h, share in fit["steps"]:
        assert h == 0.5 * (lo + hi)
        assert share == occupancy_trace("independent:dungeon", s, h, starts=("free", "occupied"))["share"]
        lo, hi = (h, hi) if share < lam else (lo, h)
    assert fit["bias"] == 0.5 * (lo + hi)
    assert fit["share"] == occupancy_trace("independent:dungeon", s, fit["bias"])["share"]


@pytest.mark.parametrize(
    ("kwargs", "option", "limit"),
    [
        ({"settings": BiasSettings(window=2)}, "window", "between 4"),
        ({"settings": BiasSettings(sweeps=10, every=6)}, "sweeps", "between 12"),
        ({"settings": BiasSettings(bias_steps=0)}, "bias_steps", "between 1"),
        ({"settings": BiasSettings(bias_range=-1.0)}, "bias_range", "(0, 100]"),
        ({"priors": ["border_bo:dungeon"]}, "priors", "takes kinds"),
        ({"priors": ["nope"]}, "priors", "not a prior kind"),
        ({"train": ["mars"]}, "train", "generated, houseexpo"),
        ({"priors": ["patch5@cal"], "train": ["generated"]}, "priors", "nothing to fit"),
    ],
)
def test_bad_options_are_named_and_nothing_is_written(tmp_path, kwargs, option, limit):
    kw = {"priors": ["independent"], "train": ["dungeon"], **kwargs}
    with pytest.raises(FitOptionError) as e:
        fit_bias(kw.pop("priors"), tmp_path / "out", **kw)
    assert e.value.option == option and limit in str(e.value)
    assert not (tmp_path / "out").exists()


def test_the_command_refuses_a_bad_option_in_one_line(tmp_path, capsys):
    argv = ["fit-prior", "bias", "--priors", "independent", "--train", "dungeon", "--window", "2"]
    assert ogm_ppl([*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ogm-ppl: error: --window") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
