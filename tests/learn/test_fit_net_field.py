"""fit_net_field at tiny settings: writes a net field of one's own plan files that loads and scores its chosen
step's held-out value, an interrupted fit resumes from its checkpoint to the same file, refused options named,
nothing written outside the folder named, the command line."""

import json

import numpy as np
import pytest

import ogm_ppl.priors.learn_net as ln
from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.learn import FitOptionError, NetFieldSettings, fit_net_field
from ogm_ppl.priors.net_field import NetFieldPrior, load_net_field, net_from_file
from tests.learn._helpers import PIXEL_SIZE, files_under, fitted_dir_listing, plan_folder, read_plans

TINY = NetFieldSettings(
    w=3,
    hidden=1,
    pl_steps=12,
    pl_batch=256,
    pcd_steps=6,
    pcd_chains=2,
    pcd_size=16,
    pcd_sweeps=1,
    eval_every=6,
    check_size=20,
    check_sweeps=5,
)
FILES = {"net_plans.npz", "net_plans.json"}


def _fit(plans, out, **kw):
    return fit_net_field(plans, out, settings=TINY, pixel_size=PIXEL_SIZE, validation_every=2, progress=False, **kw)


def test_net_field_of_own_plans_loads_and_scores_its_chosen_step(tmp_path):
    plans = plan_folder(tmp_path)
    shipped = fitted_dir_listing()
    r = _fit(plans, tmp_path / "out")
    assert files_under(tmp_path / "out") == FILES
    assert {p for p in files_under(tmp_path) if not p.startswith("plans/")} == {f"out/{f}" for f in FILES}
    assert fitted_dir_listing() == shipped
    info = json.loads(r.files[1].read_text())
    assert [row["step"] for row in info["curve"]] == [6, 12, 18]
    assert [row["phase"] for row in info["curve"]] == ["pl", "pl", "pcd"]
    assert info["chosen_step"] in (6, 12, 18) and info["heldout_nll"] == min(r["heldout_nll"] for r in info["curve"])
    d = load_net_field(r.files[0])
    assert d["w"] == 3 and d["filters"].shape == (1, 3, 3) and d["activation"] == "relu"
    # the written field's held-out score is the chosen step's, on plan 1 (the validation plan)
    prior = net_from_file(r.files[0], (16, 16))
    assert isinstance(prior, NetFieldPrior)
    val = [(p.occupancy, p.known) for p in read_plans(plans)][1:]
    nll, _ = ln.heldout_nll(lambda shape: net_from_file(r.files[0], shape).compiled(), val, 3)
    assert abs(nll - info["heldout_nll"]) < 1e-12
    cmd = info["provenance"]["command"]
    assert cmd.startswith("ogm-ppl fit-prior net-field --plan-files ") and "--w 3" in cmd and "--pl-steps 12" in cmd
    assert [c["start"] for c in info["sampler_check"]] == ["free", "occupied", "noise"]


def test_an_interrupted_fit_resumes_from_its_checkpoint_to_the_same_file(tmp_path, monkeypatch):
    plans = plan_folder(tmp_path)
    whole = _fit(plans, tmp_path / "whole")
    real, calls = ln.advance_chains, []

    def interrupted(*a, **k):
        calls.append(1)
        if len(calls) == 3:  # in the PCD stage, after the checkpoint at step 12
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(ln, "advance_chains", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _fit(plans, tmp_path / "out")
    assert files_under(tmp_path / "out") == {"net_plans.checkpoint.npz"}
    monkeypatch.setattr(ln, "advance_chains", real)
    resumed = _fit(plans, tmp_path / "out")
    assert files_under(tmp_path / "out") == FILES  # the checkpoint is gone
    assert resumed.files[0].read_bytes() == whole.files[0].read_bytes()
    a, b = (json.loads(f.files[1].read_text())["curve"] for f in (whole, resumed))
    assert a == b


@pytest.mark.parametrize(
    ("settings", "kwargs", "option", "limit"),
    [
        (NetFieldSettings(w=12), {}, "w", "between 2 and 9"),
        (NetFieldSettings(activation="tanh"), {}, "activation", "relu"),
        (NetFieldSettings(hidden=0), {}, "hidden", "between 1 and 64"),
        (NetFieldSettings(w=5, pcd_size=8), {}, "pcd_size", "between 10"),
        (TINY, {"validation_every": 10}, "validation_every", "at most 2"),
    ],
)
def test_bad_options_are_named_with_their_limit_and_nothing_is_written(tmp_path, settings, kwargs, option, limit):
    plans = plan_folder(tmp_path)
    args = {"pixel_size": PIXEL_SIZE, "validation_every": 2, "progress": False, **kwargs}
    with pytest.raises(FitOptionError) as e:
        fit_net_field(plans, tmp_path / "out", settings=settings, **args)
    assert e.value.option == option and limit in str(e.value)
    assert not (tmp_path / "out").exists()


def test_the_command_fits_a_net_field(tmp_path, capsys):
    plans = plan_folder(tmp_path)
    out = tmp_path / "o"
    argv = ["fit-prior", "net-field", "--plan-files", str(plans), "--pixel-size", "0.025", "--out", str(out)]
    argv += ["--quiet", "--validation-every", "2", "--w", "3", "--hidden", "1", "--pl-steps", "4", "--pl-batch", "64"]
    argv += ["--pcd-steps", "2", "--pcd-chains", "2", "--pcd-size", "16", "--eval-every", "2", "--check-size", "20"]
    argv += ["--check-sweeps", "2"]
    assert ogm_ppl(argv) == 0
    assert "net_plans.npz" in capsys.readouterr().out
    assert files_under(out) == FILES
    assert load_net_field(out / "net_plans.npz")["filters"].shape == (1, 3, 3)
    shipped = fitted_dir_listing()
    assert ogm_ppl(["fit-prior", "net-field", "--plan-files", str(plans), "--ship"]) == 2  # --ship needs --corpus
    assert "--corpus" in capsys.readouterr().err and fitted_dir_listing() == shipped
    assert np.isfinite(json.loads((out / "net_plans.json").read_text())["heldout_nll"])
    # --sample draws from a corpus by name only, refused before anything is read or written
    assert ogm_ppl(["fit-prior", "net-field", "--plan-files", str(plans), "--sample", "2", "--out", str(out)]) == 2
    assert "sample: applies to a floor-plan corpus by name only" in capsys.readouterr().err


def test_a_fit_into_the_package_folder_records_ship_not_a_path(tmp_path, monkeypatch):
    """A corpus's fit written where the package keeps its net fields (``--ship``) records ``--ship``: a shipped
    record holds no machine's folder."""
    import ogm_ppl.priors.net_field as nf

    monkeypatch.setattr(nf, "net_path", lambda corpus: tmp_path / "fitted" / f"net_{corpus}.npz")
    r = fit_net_field(
        "houseexpo", tmp_path / "fitted", settings=TINY, limit=4, name="houseexpo", validation_every=2, progress=False
    )
    cmd = json.loads(r.files[1].read_text())["provenance"]["command"]
    assert cmd.startswith("ogm-ppl fit-prior net-field --corpus houseexpo --limit 4 ") and cmd.endswith(" --ship")
    assert str(tmp_path) not in cmd and "--out" not in cmd and "--name" not in cmd


def test_the_command_names_a_bad_option_as_it_is_spelled(tmp_path, capsys):
    out = tmp_path / "o"
    for bad, says in (
        (["--check-size", "16"], "--check-size: must be between 17 and 1024, got 16"),
        (["--lambda", "-1"], "--lambda: must lie in [0, 1000]"),
        (["--sample", "5", "--sample-seed", "-1"], "--sample-seed: must be at least 0, got -1"),
        (["--sample-seed", "3"], "--sample-seed: applies with --sample only"),  # it picked nothing
    ):
        assert ogm_ppl(["fit-prior", "net-field", "--corpus", "houseexpo", "--out", str(out), *bad]) == 2
        assert f"ogm-ppl: error: {says}" in capsys.readouterr().err
    assert not out.exists()


def test_a_fit_started_from_a_file_tempers_it_and_stops_on_the_unseen_cell_score(tmp_path):
    """``start`` (pseudo-likelihood skipped), ``start_beta`` (the start's output weights and unary bias times
    beta), PCD chains from noise, and ``select="unseen"``: every evaluation scores the unseen-cell NLL of the
    scanned validation window, the tempered start (step 0) among them, and the written field is the least's. A
    start of another window side is refused, naming ``start``, before anything is written."""
    from dataclasses import replace

    from ogm_ppl.learn._net_select import selection_scenes, unseen_nll

    plans = plan_folder(tmp_path)
    first = _fit(plans, tmp_path / "first")
    s = replace(TINY, start=str(first.files[0]), pl_steps=0, start_beta=0.5, pcd_init="noise", select="unseen")
    s = replace(s, select_plans=1, select_window=32, select_sweeps=2, pcd_steps=4, eval_every=2)
    r = fit_net_field(plans, tmp_path / "out", settings=s, pixel_size=PIXEL_SIZE, validation_every=2, progress=False)
    info = json.loads(r.files[1].read_text())
    assert [(row["step"], row["phase"]) for row in info["curve"]] == [(0, "start"), (2, "pcd"), (4, "pcd")]
    scores = [row["unseen_nll_bits"] for row in info["curve"]]
    assert info["selected_by"] == "unseen" and info["unseen_nll_bits"] == min(scores)
    assert info["chosen_step"] == info["curve"][scores.index(min(scores))]["step"]
    d0, d = load_net_field(first.files[0]), load_net_field(r.files[0])
    if info["chosen_step"] == 0:  # the tempered start itself
        np.testing.assert_array_equal(d["out"], 0.5 * d0["out"])
    val = [(p.occupancy, p.known) for p in read_plans(plans)][1::2]
    sel = selection_scenes(val, ["p1"], 1, 32, 2)
    tempered = NetFieldPrior((4, 4), d0["filters"], d0["bias"], 0.5 * d0["out"], 0.5 * d0["unary"])
    assert unseen_nll(lambda shape: tempered.with_shape(shape), sel) == scores[0]
    with pytest.raises(FitOptionError, match="w=3") as e:
        fit_net_field(plans, tmp_path / "bad", settings=replace(s, w=5, pcd_size=16), pixel_size=PIXEL_SIZE,
                      validation_every=2, progress=False)  # fmt: skip
    assert e.value.option == "start" and not (tmp_path / "bad").exists()
