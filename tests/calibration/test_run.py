"""ogm_ppl.calibration.calibrate on tiny settings: the matrix runs and writes what it promises, a rerun resumes
(and refuses other settings), --diagonal, biased priors, plan files, a prior of one's own, and refusals before
any work."""

import dataclasses
import json
import math

import pytest
import torch

from ogm_ppl.calibration import (
    BiasFileError,
    GuideNameError,
    PriorNameError,
    SettingsError,
    SettingsMismatchError,
    calibrate,
)
from ogm_ppl.calibration import run as run_module
from ogm_ppl.datasets.plan_files import PlanFileError
from tests._plan_folder import write_plan_folder
from tests.calibration._tiny import tiny

OGM = "traditional OGM (p21)"


@pytest.fixture(autouse=True)
def _threads():
    threads = torch.get_num_threads()
    yield
    torch.set_num_threads(threads)


def test_tiny_matrix_writes_rows_tables_figures_and_resumes(tmp_path, monkeypatch):
    res = calibrate(tiny(), tmp_path, progress=False, command="ogm-ppl calibrate (tiny)")
    rows = res.rows
    names = [OGM, "independent", "independent:houseexpo", "mrf:houseexpo", "patch3:houseexpo"]
    for test in ("houseexpo", "generated"):
        sel = [r for r in rows if r["test"] == test]
        assert [r["prior_name"] for r in sel if r["mask"] == "unseen"] == names
        by = {(r["prior_name"], r["mask"]): r for r in sel}
        for name in names:
            near, unseen = by[name, "near"], by[name, "unseen"]
            assert 0 < unseen["cells"] < near["cells"] <= 36 * 36
            for r in (near, unseen):
                assert r["nll_bits"] > 0 and 0 <= r["ece"] <= 1 and 0 <= r["brier"] <= 1 and r["seconds"] >= 0
                assert sum(r["reliability"]["count"]) == r["cells"]
            if name != OGM:
                assert 0 <= unseen["rhat_below"] <= 1 and unseen["rhat_cells"] == unseen["cells"]
                v = unseen["rhat_below_varying"]
                assert (0 <= v <= unseen["rhat_below"]) or math.isnan(v)  # frozen cells count as agreeing
        assert by["patch3:houseexpo", "unseen"]["patch"] == [3, 3] and by["mrf:houseexpo", "unseen"]["patch"] is None
        assert by["independent", "unseen"]["train"] == "none"
    doc = json.loads((tmp_path / "calibration.json").read_text())
    brief = json.loads((tmp_path / "calibration_summary.json").read_text())
    assert len(brief["summary"]) == 2 * 2 * len(names) and "reliability" not in brief["summary"][0]
    spread = brief["summary"][0]["spread"]["nll_bits"]  # the per-map spread beside each mean
    assert spread["min"] <= brief["summary"][0]["nll_bits"] <= spread["max"] and spread["sd"] >= 0
    assert {"command", "commit", "machine"} <= set(doc["provenance"]) and doc["settings"]["sweeps"] == 16
    assert doc["provenance"]["command"] == "ogm-ppl calibrate (tiny)" and doc["settings"] == res.settings
    assert res.path == tmp_path / "calibration.json" and len(res.summary) == len(brief["summary"])
    md = (tmp_path / "calibration.md").read_text()
    assert "| patch3:houseexpo |" in md and "Across corpora" in md
    assert (
        {p.name for p in tmp_path.glob("*.png")}
        == {p.name for p in res.figures}
        == {
            "matrix_unseen.png",
            "reliability_houseexpo.png",
            "reliability_generated.png",
            "bars_unseen.png",
            "bars_near.png",
        }
    )

    def never(*a, **k):
        raise AssertionError("a resumed run recomputed a row it had")

    monkeypatch.setattr(run_module, "run_prior", never)
    monkeypatch.setattr(run_module, "run_ogm", never)
    again = calibrate(tiny(figures=False), tmp_path, progress=False)
    assert len(again.rows) == len(rows)
    runs = json.loads((tmp_path / "calibration.json").read_text())["runs"]
    assert len(runs) == 2 and runs[0]["seconds"] == doc["runs"][0]["seconds"]
    with pytest.raises(SettingsMismatchError, match="settings differ in \\['sweeps'\\]") as e:
        calibrate(tiny(sweeps=17), tmp_path, progress=False)
    assert e.value.keys == ["sweeps"]


def test_diagonal_scores_each_corpus_with_its_own_priors_only(tmp_path):
    s = tiny(test=("houseexpo", "ipa"), train=("houseexpo", "ipa"), priors=("independent",), diagonal=True)
    rows = calibrate(dataclasses.replace(s, sweeps=4, burn=2, figures=False), tmp_path, progress=False).rows
    got = sorted({(r["test"], r["prior_name"]) for r in rows})
    assert got == [
        ("houseexpo", "independent"),
        ("houseexpo", "independent:houseexpo"),
        ("houseexpo", OGM),
        ("ipa", "independent"),
        ("ipa", "independent:ipa"),
        ("ipa", OGM),
    ]


def test_tempering_settings_are_recorded_only_with_its_kernel(tmp_path):
    def settings(name, **over):
        s = tiny(test=("houseexpo",), priors=("independent",), figures=False, **over)
        return calibrate(s, tmp_path / name, progress=False).settings

    assert not {"rungs", "beta_min", "temper"} & set(settings("gibbs"))
    got = settings("tempering", kernel="tempering", rungs=2)
    assert got["kernel"] == "tempering" and got["rungs"] == 2 and got["temper"] == "prior"


def test_a_bias_file_runs_each_named_prior_biased_beside_it(tmp_path):
    """``bias_file``: the priors it names run again as ``NAME+bias``. A zero bias is the prior itself (the same
    chain from the same seed, so the same scores); a bias of +3 raises the mean marginal of the unseen cells; the
    biases are settings a resume must share; a malformed file is refused naming it."""
    bias = tmp_path / "bias.json"

    def run(out, **over):
        s = tiny(test=("houseexpo",), priors=("patch3",), bias_file=bias, figures=False, **over)
        return calibrate(s, tmp_path / out, progress=False).rows

    bias.write_text(json.dumps({"format": "ogm_ppl.prior_bias", "bias": {"patch3:houseexpo": 0.0}}))
    rows = run("zero")
    by = {(r["prior_name"], r["mask"]): r for r in rows}
    assert by["patch3:houseexpo+bias", "unseen"]["prior"] == "patch3+bias"
    for mask in ("unseen", "near"):
        a, b = by["patch3:houseexpo", mask], by["patch3:houseexpo+bias", mask]
        assert (a["nll_bits"], a["auc"], a["rhat_below"]) == (b["nll_bits"], b["auc"], b["rhat_below"])
    bias.write_text(json.dumps({"format": "ogm_ppl.prior_bias", "bias": {"patch3:houseexpo": 3.0}}))
    with pytest.raises(SettingsMismatchError, match="settings differ in \\['bias'\\]"):
        run("zero")
    rows = run("three")
    occ = {r["prior_name"]: r for r in rows if r["mask"] == "unseen"}
    mean_q = {k: sum(r["reliability"]["sum_q"]) / sum(r["reliability"]["count"]) for k, r in occ.items()}
    assert mean_q["patch3:houseexpo+bias"] > mean_q["patch3:houseexpo"] + 0.2  # +3 log-odds fills the unseen cells
    bias.write_text('{"format": "ogm_ppl.prior_bias", "bias": {"patch3:houseexpo": "high"}}')
    with pytest.raises(BiasFileError, match=f"{bias}: not a bias file"):
        run("bad")


PLAN_RUN = dict(
    train=("houseexpo",),
    priors=("independent", "patch3"),
    diagonal=True,
    plans=5,
    window=36,
    poses=2,
    beams=45,
    range_cells=30.0,
    sweeps=8,
    burn=2,
    figures=False,
    plan_set="mine",
    pixel_size=0.025,
)


def test_plan_files_are_one_more_test_set_scored_with_every_prior(tmp_path):
    from ogm_ppl.calibration import CalibrationSettings, plan_file_maps

    d = write_plan_folder(tmp_path)
    res = calibrate(CalibrationSettings(**PLAN_RUN, plan_files=(d,)), tmp_path / "out", progress=False)
    rows = res.rows
    assert {r["test"] for r in rows} == {"mine"}  # no corpus runs unless test names one
    assert sorted({r["plan"].split("@")[0] for r in rows}) == ["hall", "office"]
    # diagonal limits the corpora's own priors; a plan set has none, so every prior runs on it
    assert {r["prior_name"] for r in rows} == {
        OGM,
        "independent",
        "independent:houseexpo",
        "patch3:houseexpo",
        "guide:houseexpo+ipa@sym",  # without guides, the floor-plan guide
    }
    for r in rows:
        assert r["nll_bits"] > 0 and 0 < r["cells"] <= 36 * 36
    md = (tmp_path / "out" / "calibration.md").read_text()
    assert "**mine**, unseen cells (2 maps)" in md and "| patch3:houseexpo |" in md.split("**mine**, near")[0]
    settings = json.loads((tmp_path / "out" / "calibration.json").read_text())["settings"]
    assert settings["plan_files"] == [str(d)] and settings["plan_set"] == "mine" and settings["test"] == []
    assert {r["plan"] for r in rows} == {t.name for t in plan_file_maps([d], 5, 36, 0.025, "mine")}


def test_runs_without_plan_files_keep_their_settings(tmp_path):
    s = tiny(test=("generated",), priors=("independent",), quick=True, figures=False)
    settings = calibrate(s, tmp_path, progress=False).settings
    assert not {"plan_files", "plan_set", "pixel_size"} & set(settings)
    assert settings["quick"] is True and settings["window"] == 48 and settings["plans"] == 1


def test_a_changed_plan_file_refuses_to_resume_and_bad_files_are_named(tmp_path):
    import numpy as np
    from PIL import Image

    from ogm_ppl.calibration import CalibrationSettings

    d = write_plan_folder(tmp_path)
    s = CalibrationSettings(**{**PLAN_RUN, "priors": ("independent",)}, plan_files=(d,))
    calibrate(s, tmp_path / "out", progress=False)
    calibrate(s, tmp_path / "out", progress=False)  # unchanged files: resumes, nothing to run
    px = np.asarray(Image.open(d / "office.png")).copy()
    px[40:44, 40:120] = 0  # a wall added to the plan
    Image.fromarray(px).save(d / "office.png")
    with pytest.raises(SettingsMismatchError, match="settings differ in \\['plan_digests'\\]"):
        calibrate(s, tmp_path / "out", progress=False)
    (tmp_path / "bad").mkdir()
    bad = CalibrationSettings(**PLAN_RUN, plan_files=(tmp_path / "bad",))
    (tmp_path / "bad" / "junk.png").write_bytes(b"no image")
    with pytest.raises(PlanFileError, match=r"junk\.png: unreadable image"):
        calibrate(bad, tmp_path / "out2", progress=False)
    (tmp_path / "bad" / "walls.json").write_text('{"verts": [[0, 0], [4, 0]]')  # cut short
    (tmp_path / "bad" / "room.png").write_bytes((d / "office.png").read_bytes())  # a good plan among them
    with pytest.raises(PlanFileError) as e:  # every bad file is named, one a line
        calibrate(bad, tmp_path / "out2", progress=False)
    lines = str(e.value).splitlines()
    assert len(lines) == 2 and "junk.png: unreadable image" in lines[0] and "walls.json: " in lines[1]


def test_a_prior_of_ones_own_runs_once_and_reruns_when_it_changes(tmp_path, monkeypatch):
    """A registered kind named without a corpus runs once (trained on ``own``); a rerun computes again the rows
    of a prior that changed since (and only those); an unknown name stops the run before any work."""
    from ogm_ppl.calibration import prior_names
    from ogm_ppl.priors import named
    from tests.priors.toy_checkerboard import KIND, CheckerboardPrior

    small = tiny(test=("generated",), priors=(KIND, "independent"), figures=False)
    assert prior_names([KIND, f"{KIND}:ipa"], ["houseexpo"]) == [(KIND, "own"), (f"{KIND}:ipa", "ipa")]
    first = calibrate(small, tmp_path, progress=False).rows
    mine = [r for r in first if r["prior_name"] == KIND]
    assert len(mine) == 2 and {r["train"] for r in mine} == {"own"} and mine[0]["prior"] == KIND
    assert f"| {KIND} |" in (tmp_path / "calibration.md").read_text()  # in the test corpus's own table
    calls = []
    real = run_module.run_prior
    monkeypatch.setattr(
        run_module, "run_prior", lambda scene, name, *a, **k: calls.append(name) or real(scene, name, *a, **k)
    )
    monkeypatch.setitem(named._FACTORIES, KIND, lambda shape, tables: CheckerboardPrior(shape, beta=2.0))
    again = calibrate(small, tmp_path, progress=False).rows
    assert calls == [KIND] and len(again) == len(first)
    assert [r["nll_bits"] for r in again if r["prior_name"] == KIND] != [r["nll_bits"] for r in mine]

    def never(*a, **k):
        raise AssertionError("work started before the prior names were checked")

    monkeypatch.setattr(run_module, "run_ogm", never)
    with pytest.raises(PriorNameError, match="unknown prior kind 'no_such_kind'"):
        calibrate(tiny(priors=("no_such_kind",)), tmp_path / "x", progress=False)
    assert not (tmp_path / "x").exists()  # refused before anything was made
    with pytest.raises(GuideNameError, match="a corpus guide is named CORPUS"):
        calibrate(tiny(guides=("ipa@cal",)), tmp_path / "x", progress=False)
    assert not (tmp_path / "x").exists()
    (tmp_path / "file").write_text("x")
    with pytest.raises(SettingsError, match=r"^out: .*exists and is not a folder") as e:
        calibrate(small, tmp_path / "file", progress=False)
    assert e.value.option == "out"


def test_a_proposal_guide_that_cannot_be_read_is_refused_by_its_option_before_any_work(tmp_path, monkeypatch):
    def never(*a, **k):
        raise AssertionError("work started before the proposal guide was read")

    monkeypatch.setattr(run_module, "run_ogm", never)
    s = tiny(test=("houseexpo",), priors=("independent",), kernel="guided", proposal_guide="nope")
    with pytest.raises(SettingsError, match=r"^proposal_guide: .*guide_nope\.npz: no such file") as e:
        calibrate(s, tmp_path / "x", progress=False)
    assert e.value.flag == "--proposal-guide"
    assert not (tmp_path / "x").exists()
