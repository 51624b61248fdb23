"""fit_field at tiny settings: the field of one's own plan files equals the learn_field stages run by hand on
the same split, loads through field_from_file at one and two scales, an interrupted fit resumes from its
checkpoint to the same file, refused options named, nothing written outside the folder named, the command."""

import json

import numpy as np
import pytest

import ogm_ppl.priors.learn_field as lf
from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.learn import FieldSettings, FitOptionError, fit_field
from ogm_ppl.priors.pattern_field import PatternFieldPrior, field_from_file, load_field
from tests.learn._helpers import PIXEL_SIZE, files_under, fitted_dir_listing, plan_folder, read_plans

TINY = FieldSettings(
    betas=(0.5, 0.7),
    bias_steps=1,
    pl_max_iter=15,
    check_size=24,
    check_chains=2,
    check_sweeps=20,
    report_sizes=(24,),
    report_sweeps=20,
)
FILES = {"field_plans.npz", "field_plans.json"}


def _fit(plans, out, **kw):
    return fit_field(plans, out, settings=TINY, pixel_size=PIXEL_SIZE, validation_every=2, progress=False, **kw)


def test_field_of_own_plans_equals_the_stages_by_hand_and_loads(tmp_path):
    plans = plan_folder(tmp_path)
    shipped = fitted_dir_listing()
    r = _fit(plans, tmp_path / "out")
    assert files_under(tmp_path / "out") == FILES
    assert {p for p in files_under(tmp_path) if not p.startswith("plans/")} == {f"out/{f}" for f in FILES}
    assert fitted_dir_listing() == shipped
    # the independent route: plan 0 trains, plan 1 validates; the stages of ogm_ppl.priors.learn_field
    tr_p, va_p = [(p.occupancy, p.known) for p in read_plans(plans)]
    tr, va = lf.field_stats([tr_p], 3, 2), lf.field_stats([va_p], 3, 2)
    phi, _, _ = lf.fit_pl(lf.field_stats([tr_p], 2, 1), 1, TINY.backoff_lambda_, TINY.pl_max_iter, progress=False)
    theta0 = lf.backoff_potentials(phi, 2, 3)
    occ = float(tr.win1 @ ((np.arange(512) >> 4) & 1) / tr.win1.sum())
    d = load_field(r.files[0])
    for scales, keys in ((1, ("theta", None)), (2, ("theta2_scale1", "theta2_scale2"))):
        th, th2, _ = lf.fit_pl(tr, scales, TINY.lambda_, TINY.pl_max_iter, theta0=theta0, progress=False)
        want = lf.fit_tempered(
            va, th, th2, betas=TINY.betas, occupancy=occ, bias_steps=1, size=24, chains=2, sweeps=20, progress=False
        )
        assert np.array_equal(d[keys[0]], want.theta)
        if keys[1]:
            assert np.array_equal(d[keys[1]], want.theta2)
        assert r.summary[f"scales{scales}"]["beta"] == want.beta
    for scales in (1, 2):
        prior = field_from_file(r.files[0], (16, 16), scales=scales)
        assert isinstance(prior, PatternFieldPrior) and (prior.theta2 is not None) == (scales == 2)
    info = json.loads(r.files[1].read_text())
    assert info["settings"]["betas"] == [0.5, 0.7] and info["train_maps"] == 1 and info["validation_maps"] == 1
    cmd = info["provenance"]["command"]
    assert (
        cmd.startswith("ogm-ppl fit-prior field --plan-files ")
        and "--betas 0.5 0.7" in cmd
        and "--check-size 24" in cmd
    )
    assert set(info["sampler_check"]) == {"validation_window_centre_occupied_share", "scales1", "scales2"}


def test_an_interrupted_fit_resumes_from_its_checkpoint_to_the_same_file(tmp_path, monkeypatch):
    plans = plan_folder(tmp_path)
    whole = _fit(plans, tmp_path / "whole")
    real, calls = lf.fit_tempered, []

    def interrupted(*a, **k):
        calls.append(1)
        if len(calls) == 2:  # the two-scale search
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(lf, "fit_tempered", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _fit(plans, tmp_path / "out")
    assert files_under(tmp_path / "out") == {"field_plans.checkpoint.json"}
    monkeypatch.setattr(lf, "fit_tempered", real)
    resumed = _fit(plans, tmp_path / "out")
    assert files_under(tmp_path / "out") == FILES  # the checkpoint is gone
    assert resumed.files[0].read_bytes() == whole.files[0].read_bytes()  # same seed, same field
    for k, fit in json.loads(resumed.files[1].read_text())["fits"].items():  # all but the wall-clock seconds
        assert {**fit, "seconds": 0} == {**json.loads(whole.files[1].read_text())["fits"][k], "seconds": 0}


@pytest.mark.parametrize(
    ("settings", "kwargs", "option", "limit"),
    [
        (FieldSettings(check_size=8), {}, "check_size", "between 17 and 1024"),
        (FieldSettings(betas=()), {}, "betas", "at least one"),
        (FieldSettings(betas=(0.5, -1.0)), {}, "betas", "(0, 10]"),
        (FieldSettings(w=3, backoff_w=3), {}, "backoff_w", "between 1 and 2"),
        (FieldSettings(check_sweeps=5), {}, "check_sweeps", "between 10"),
        (TINY, {"validation_every": 10}, "validation_every", "at most 2"),
    ],
)
def test_bad_options_are_named_with_their_limit_and_nothing_is_written(tmp_path, settings, kwargs, option, limit):
    plans = plan_folder(tmp_path)
    args = {"pixel_size": PIXEL_SIZE, "validation_every": 2, "progress": False, **kwargs}
    with pytest.raises(FitOptionError) as e:
        fit_field(plans, tmp_path / "out", settings=settings, **args)
    assert e.value.option == option and limit in str(e.value)
    assert not (tmp_path / "out").exists()


def test_the_command_fits_a_field(tmp_path, capsys):
    plans = plan_folder(tmp_path)
    out = tmp_path / "o"
    argv = ["fit-prior", "field", "--plan-files", str(plans), "--pixel-size", "0.025", "--out", str(out), "--quiet"]
    argv += ["--validation-every", "2", "--betas", "0.5", "0.7", "--bias-steps", "1", "--pl-max-iter", "15"]
    argv += ["--check-size", "24", "--check-chains", "2", "--check-sweeps", "20"]
    argv += ["--report-sizes", "24", "--report-sweeps", "20"]
    assert ogm_ppl(argv) == 0
    assert "field_plans.npz" in capsys.readouterr().out
    assert files_under(out) == FILES
    assert load_field(out / "field_plans.npz")["w"] == 3
