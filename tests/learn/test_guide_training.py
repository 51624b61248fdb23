"""ogm_ppl.learn's corpus guide training (``train_corpus_guide``, ``ogm-ppl train-guide``) on tiny settings: it
trains on the tables' training plans only (or plan files of one's own), records them, keeps the validation-best
step, resumes bit for bit, refuses bad options naming them, and the calibration run scores the artefact
(``--guides``) or refuses one whose record is not the tables' training set."""

import argparse
import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pytest
import torch

from ogm_ppl.calibration import leakage
from ogm_ppl.calibration import run as run_module
from ogm_ppl.cli import train_guide as command
from ogm_ppl.inference.variational.amortised import AmortisedGuide
from ogm_ppl.learn import (
    CheckpointError,
    GuideSettingsError,
    GuideTrainingSettings,
    train_corpus_guide,
)
from ogm_ppl.learn import guide_examples as ge
from ogm_ppl.learn import guide_settings as gs
from ogm_ppl.learn import guide_training as gt
from tests._experiments import run_script
from tests._plan_folder import write_plan_folder

SMALL = GuideTrainingSettings(
    corpus=("ipa",), examples=6, val=2, window=40, poses=2, beams=45, range_cells=30, channels=4, dilations=(1, 2, 1)
)
SMALL_FLAGS = (
    "--examples 6 --val 2 --window 40 --poses 2 --beams 45 --range-cells 30 --channels 4 --dilations 1 2 1".split()
)


def small(**kw) -> GuideTrainingSettings:
    return dataclasses.replace(SMALL, **kw)


@pytest.fixture(scope="module")
def cal():
    """The calibration package (the leakage checks, ``guide_path``, ``load_corpus_guide``, ``calibrate``)."""
    import ogm_ppl.calibration as calibration

    return calibration


def _calibrate(argv: list[str]):
    """The calibration run with the options of ``ogm-ppl calibrate``."""
    from ogm_ppl.calibration import calibrate
    from ogm_ppl.cli.calibrate import build_parser, settings_from_args

    args = build_parser().parse_args(argv)
    return calibrate(settings_from_args(args), args.out, progress=False)


@pytest.fixture(scope="module")
def artefact(tmp_path_factory):
    out = tmp_path_factory.mktemp("guide") / "g.npz"
    r = train_corpus_guide(small(steps=6, eval_every=3), out, progress=False)
    assert r.finished and r.path == out and r.sidecar == out.with_suffix(".json")
    return out, r.record


def _weights_equal(a, b) -> bool:
    sa, sb = AmortisedGuide.load(a).net.state_dict(), AmortisedGuide.load(b).net.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def test_training_uses_the_tables_plans_and_records_them(artefact):
    out, meta = artefact
    train, val = ge.split_plans("ipa")
    names = leakage.training_set("ipa")
    assert set(train) | set(val) == names and not set(train) & set(val) and val == sorted(names)[::5]
    assert meta["plan_names_sha256"] == leakage.names_digest(names) and meta["corpus"] == "ipa"
    side = json.loads(out.with_suffix(".json").read_text())
    steps = [h["step"] for h in side["history"]]
    assert steps == [3, 6]
    best = min(side["history"], key=lambda h: h["bits_per_unseen_cell"])
    assert side["training"]["kept_step"] == best["step"]
    v = side["validation"]
    assert math.isclose(v["before_temperature"], best["bits_per_unseen_cell"])
    assert v["bits_per_unseen_cell"] <= v["before_temperature"] + 1e-9  # T = 1 is one of the temperatures tried
    assert 0.25 <= side["training"]["temperature"] <= 4
    assert 0 < best["bits_per_cell"] < 10 and best["unseen_cells"] > 0
    # the record names the command that makes it, and the sidecar the file's digest
    cmd = side["provenance"]["command"]
    assert cmd.startswith("ogm-ppl train-guide --corpus ipa --examples 6 --val 2 --window 40") and str(out) in cmd
    assert AmortisedGuide.load(out).trained_for["provenance"]["command"] == cmd
    import hashlib

    assert side["sha256"] == hashlib.sha256(out.read_bytes()).hexdigest() and side["file"] == "g.npz"


def test_the_kept_weights_reproduce_the_recorded_validation_loss(artefact):
    """Rebuilding the validation set from the same seed and scoring the saved guide gives the recorded loss."""
    out, meta = artefact
    _, val = ge.split_plans("ipa")
    exs = ge.build_set(ge.corpus_source("ipa"), val, 2, SMALL, 0 + 1, "validation")
    got = gt.losses(AmortisedGuide.load(out), exs)
    assert got["bits_per_unseen_cell"] == pytest.approx(meta["validation"]["bits_per_unseen_cell"], rel=1e-5)


def test_the_temperature_is_folded_into_the_logits():
    g = AmortisedGuide(channels=3, dilations=(1,), phase=(0, 0), seed=1)
    x = torch.randn(1, 7, 9, 9, dtype=torch.float32)
    net = g.net
    with torch.no_grad():
        before = net(x)[0].clone()
        h = x
        for conv in net.convs:
            h = torch.relu(conv(h))
        # per cell, the sizes of the terms the head and the skip add up (their biases included)
        size = (
            torch.nn.functional.conv2d(h.abs(), net.head.weight.abs(), net.head.bias.abs())
            + torch.nn.functional.conv2d(x.abs(), net.skip.weight.abs(), net.skip.bias.abs())
        )[0, 0].double()
        terms = net.head.in_channels + net.skip.in_channels + 2
    # the truth is sharper than the logits, so the temperature is below 1
    y = (torch.rand(9, 9, dtype=torch.float32) < torch.sigmoid(3 * before)).float()
    e = ge.Example(x=x[0], y=y, scored=torch.ones(9, 9, dtype=torch.bool), unseen=torch.ones(9, 9, dtype=torch.bool))
    t = gt.fit_temperature(g, [e])
    assert 0.25 <= t < 1
    # the folded logits sum float32 terms rounded (weights / T) and summed afresh, in an order the CPU's
    # kernels choose, against the logits rounded once more by / T: each side is off the exact value by at
    # most (terms + 2) eps32 of the terms' sizes / T
    bound = 2 * (terms + 2) * torch.finfo(torch.float32).eps * size / t
    assert ((g.net(x)[0].detach().double() - (before / t).double()).abs() <= bound).all()


def test_a_symmetry_turns_features_and_truth_together():
    x = torch.arange(2 * 3 * 4, dtype=torch.float32).reshape(2, 3, 4)
    y = x[0].clone()
    e = ge.Example(x=x, y=y, scored=y > 3, unseen=y > 7)
    for sym in range(8):
        bx, by, bs, bu = ge.batch([e], sym)
        assert torch.equal(bx[0, 0], by[0]) and torch.equal(bs[0], by[0] > 3) and torch.equal(bu[0], by[0] > 7)
    assert ge.batch([e], 1)[1].shape == (1, 4, 3) and torch.equal(ge.batch([e], 4)[1][0], y.flip(-1))


def test_calibration_scores_the_guide_and_refuses_another_record(cal, artefact, tmp_path, monkeypatch):
    """``--guide-dir DIR`` reads ``DIR/guide_C.npz`` and checks its record as it checks a shipped guide's."""
    import shutil

    out, _ = artefact
    shutil.copy(out, tmp_path / "guide_ipa.npz")
    assert cal.guide_path("ipa", tmp_path) == tmp_path / "guide_ipa.npz"
    assert cal.guide_path("ipa") == leakage.FITTED_DIR / "guide_ipa.npz"
    argv = (
        "--test ipa --train ipa --priors independent --guides ipa --plans 1 --window 36 --poses 2 --beams 45 "
        "--range-cells 30 --sweeps 4 --burn 2 --no-figures"
    ).split()
    res = _calibrate([*argv, "--guide-dir", str(tmp_path), "--out", str(tmp_path / "cal")])
    assert json.loads(res.path.read_text())["settings"]["guide_dir"] == str(tmp_path)
    monkeypatch.setattr(leakage, "guide_path", lambda corpus, directory=None: out)
    rows = [r for r in res.rows if r["prior_name"] == "guide:ipa"]
    assert {r["mask"] for r in rows} == {"unseen", "near"} and all(r["prior"] == "guide" for r in rows)
    assert all(r["train"] == "ipa" and 0 < r["nll_bits"] < 10 and "rhat_below" not in r for r in rows)
    with pytest.raises(cal.LeakageError, match="names corpus 'ipa', not 'houseexpo'"):
        cal.load_corpus_guide("houseexpo")
    with pytest.raises(cal.LeakageError, match="not the training set"):
        cal.load_corpus_guide("ipa", train={"some_other_plan"})


def test_a_whole_map_scene_gives_crops_of_one_scan():
    """``scan_whole_map``: one route through the whole map, its features cropped: each crop is the whole-map
    scene's own window (features, truth, unseen cells), not a scene of its own."""
    from ogm_ppl.datasets.mapgen import generate_map

    occ = generate_map("office", (90, 90), seed=5, border=4)
    plan = ge.TrainingMap(occ, np.ones_like(occ), 0.05)
    s = small(poses=0, beams=90, scan_whole_map=True)
    exs = ge.scene_examples(plan, 3, s, np.random.default_rng(0))
    assert len(exs) == 3
    for e in exs:
        assert e.x.shape == (7, 40, 40) and e.y.shape == (40, 40)
        assert (e.y.numpy() < 0.5).sum() >= 200 and not (e.unseen & ~e.scored).any()
        # the crop sits in the map: its truth is a window of occ
        hits = [
            (r, c)
            for r in range(90 - 40 + 1)
            for c in range(90 - 40 + 1)
            if np.array_equal(occ[r : r + 40, c : c + 40], e.y.numpy() > 0.5)
        ]
        assert hits
    names = list(ge.generated_maps())
    assert len(names) == 100 and names[0].startswith("seedstream:")


def test_a_guide_of_two_corpora_records_each_training_set(cal, tmp_path, monkeypatch):
    """``corpus=("ipa", "dungeon")``: one guide named ``ipa+dungeon``, windows from both corpora's training plans,
    each corpus's training set recorded; :func:`load_corpus_guide` checks every one and refuses a record that
    lacks one or names other plans; the calibration run checks the test plans against each corpus."""
    out = tmp_path / "g2.npz"
    meta = train_corpus_guide(small(corpus=("ipa", "dungeon"), steps=2, eval_every=2), out, progress=False).record
    assert meta is not None
    assert meta["corpus"] == "ipa+dungeon" and "plan_names_sha256" not in meta
    for c in ("ipa", "dungeon"):
        assert meta["corpora"][c]["plan_names_sha256"] == cal.names_digest(cal.training_set(c))
        train, val = ge.split_plans(c)
        assert meta["corpora"][c]["training_plans"] == len(train) and meta["corpora"][c]["validation_plans"] == len(val)
    assert [gt.share(7, 2, i) for i in range(2)] == [4, 3]
    monkeypatch.setattr(leakage, "guide_path", lambda corpus, directory=None: out)
    assert cal.load_corpus_guide("ipa+dungeon").trained_for["corpus"] == "ipa+dungeon"
    with pytest.raises(cal.LeakageError, match="names corpus 'ipa\\+dungeon', not 'ipa'"):
        cal.load_corpus_guide("ipa")
    g = AmortisedGuide.load(out)
    bad = {**g.trained_for, "corpora": {"ipa": meta["corpora"]["ipa"], "dungeon": {"plan_names_sha256": "0" * 64}}}
    g.save(tmp_path / "bad.npz", bad)
    monkeypatch.setattr(leakage, "guide_path", lambda corpus, directory=None: tmp_path / "bad.npz")
    with pytest.raises(cal.LeakageError, match=r"record of dungeon .* is not the training set of the dungeon tables"):
        cal.load_corpus_guide("ipa+dungeon")
    g.save(tmp_path / "bad.npz", {**bad, "corpora": {"ipa": meta["corpora"]["ipa"]}})
    with pytest.raises(cal.LeakageError, match="does not list the training sets of ipa, dungeon"):
        cal.load_corpus_guide("ipa+dungeon")


class _FakeGuide:
    """What the calibration run reads of a guide before it scores one: its weights (for the rows' digest),
    ``symmetrize`` and its record."""

    symmetrize = False
    net = torch.nn.Linear(1, 1)
    trained_for: dict = {}


def test_calibration_checks_a_two_corpus_guide_against_each_corpus(cal, monkeypatch, tmp_path):
    """The leakage check runs for every corpus a guide was learned on: a test plan that is a training plan of
    either corpus is refused."""
    seen: list[tuple] = []
    monkeypatch.setattr(run_module, "check_heldout", lambda test, plans, train, *_: seen.append((test, train)))
    monkeypatch.setattr(run_module, "guide_training_sets", lambda name, meta: {c: set() for c in name.split("+")})
    monkeypatch.setattr(leakage, "load_corpus_guide", lambda c, directory=None: _FakeGuide())
    monkeypatch.setattr(run_module, "make_scene", lambda t, args: (_ for _ in ()).throw(SystemExit("stop")))
    with pytest.raises(SystemExit, match="stop"):
        _calibrate(
            "--test ipa --priors independent --guides ipa+dungeon --plans 1 --window 36 --no-figures --out".split()
            + [str(tmp_path)]
        )
    assert ("ipa", "ipa") in seen and ("ipa", "dungeon") in seen


def test_a_symmetrised_guide_row_loads_the_guide_symmetrised_and_checks_its_corpora(cal, monkeypatch, tmp_path):
    """``--guides C1+C2@sym``: the guide of C1+C2 with ``symmetrize`` on, its leakage checked per corpus."""
    seen: list[tuple] = []
    loaded: list = []

    def load(c, directory=None):
        loaded.append((c, _FakeGuide()))
        return loaded[-1][1]

    monkeypatch.setattr(run_module, "check_heldout", lambda test, plans, train, *_: seen.append((test, train)))
    monkeypatch.setattr(run_module, "guide_training_sets", lambda name, meta: {c: set() for c in name.split("+")})
    monkeypatch.setattr(leakage, "load_corpus_guide", load)
    monkeypatch.setattr(run_module, "make_scene", lambda t, args: (_ for _ in ()).throw(SystemExit("stop")))
    assert cal.guide_corpora("ipa+dungeon@sym") == ["ipa", "dungeon"]
    with pytest.raises(SystemExit, match="stop"):
        _calibrate(
            "--test ipa --priors independent --guides ipa+dungeon@sym ipa --plans 1 --window 36 --no-figures".split()
            + ["--out", str(tmp_path)]
        )
    assert [(c, g.symmetrize) for c, g in loaded] == [("ipa+dungeon", True), ("ipa", False)]
    for bad in ("ipa@sym@sym", "@sym", "ipa@cal"):
        with pytest.raises(leakage.GuideNameError, match="a corpus guide is named CORPUS"):
            cal.guide_for(bad)
    assert ("ipa", "ipa") in seen and ("ipa", "dungeon") in seen


def test_driven_scans_face_ahead_at_the_drawn_path_step():
    """``drive``: poses every ``S`` cells of the route's path (``S`` one of the listed steps), each scan
    ``fov`` degrees ahead with beams ``360 / beams`` apart; a denser drive reaches more cells."""
    from ogm_ppl import Grid, raycast
    from ogm_ppl.datasets import drive_route, plan_route
    from ogm_ppl.datasets.mapgen import generate_map

    occ = generate_map("office", (90, 90), seed=5, border=4)
    grid = Grid(occ.shape, 0.05)
    route = plan_route(occ, grid, max_range_cells=30, seed=1)
    s = small(scan_whole_map=True, poses=0, beams=180, fov=180.0, range_cells=30.0, sigma=0.5, drive=(4.0,))
    scans = ge.driven_scans(occ, grid, route, s, np.random.default_rng(0))
    np.testing.assert_allclose(scans.poses, drive_route(occ, grid, route, step_cells=4.0))
    assert scans.beams_per_scan == 90
    np.testing.assert_allclose(np.degrees(np.asarray(scans.angles).reshape(-1, 90)[0, [0, -1]]), [-89.0, 89.0])
    sparse = ge.driven_scans(occ, grid, route, dataclasses.replace(s, drive=(40.0,)), np.random.default_rng(0))
    assert len(sparse.poses) < len(scans.poses) / 5
    reached = [int(raycast(grid, x).reached().sum()) for x in (scans, sparse)]
    assert reached[0] > reached[1]
    with pytest.raises(GuideSettingsError, match="--drive needs --scan-whole-map"):
        small(drive=(10.0,))
    with pytest.raises(GuideSettingsError, match="finite path steps"):
        small(scan_whole_map=True, poses=0, drive=(10.0, math.nan))
    with pytest.raises(GuideSettingsError, match="--fov applies to driven scans only"):
        small(fov=180.0)
    with pytest.raises(GuideSettingsError, match="--plan-range-cells needs --scan-whole-map"):
        small(plan_range_cells=75.0)


def test_the_planner_range_sets_the_stops_not_the_scans(monkeypatch):
    """``plan_range_cells``: the route is planned for that range, the scans keep ``range_cells``."""
    import importlib

    from ogm_ppl.datasets.mapgen import generate_map

    sas = importlib.import_module("ogm_ppl.datasets.stop_and_scan")  # the module, not the function of that name

    occ = generate_map("office", (120, 120), seed=5, border=4)
    plan = ge.TrainingMap(occ, np.ones_like(occ), 0.05)
    seen = []
    real = sas.plan_route

    def spy(*a, **k):
        seen.append(k["max_range_cells"])
        return real(*a, **k)

    monkeypatch.setattr(sas, "plan_route", spy)
    for plan_range in (None, 20.0):
        s = small(poses=0, beams=90, range_cells=60.0, scan_whole_map=True, plan_range_cells=plan_range)
        ge.scene_examples(plan, 1, s, np.random.default_rng(0))
    assert seen == [60.0, 20.0]


def test_several_corpora_refuse_too_few_windows_to_share():
    """Each corpus needs a training and a validation window: ``val=1`` for two corpora is refused before any
    data are read, as is a corpus named twice."""
    with pytest.raises(GuideSettingsError, match="at least one window"):
        GuideTrainingSettings(corpus=("ipa", "dungeon"), examples=6, val=1)
    with pytest.raises(GuideSettingsError, match="names a corpus twice"):
        GuideTrainingSettings(corpus=("ipa", "ipa"))


@pytest.mark.parametrize(
    ("kw", "option", "match"),
    [
        ({"corpus": ()}, "corpus", "give --corpus, --plan-files or both"),
        ({"corpus": ("ipaa",)}, "corpus", "'ipaa' is not a corpus; choose from houseexpo"),
        ({"sample": 0}, "sample", "--sample must be a whole number of at least 1 plan, got 0"),
        ({"corpus": (), "plan_files": ("x",), "sample": 5}, "sample", "it needs --corpus"),
        ({"sample_seed": 3}, "sample_seed", "--sample-seed needs --sample"),
        ({"sample": 5, "sample_seed": -1}, "sample_seed", "--sample-seed must be a whole number of at least 0"),
        ({"name": "Real+1"}, "name", "--name must be 1-40 lower-case letters"),
        ({"name": "r2v"}, "name", "'r2v' is a corpus's name: a guide named so is learned on it alone"),
        ({"steps": 0}, "steps", "--steps must be at least 1, got 0"),
        ({"window": 2.5}, "window", "--window must be at least 1"),
        ({"window": 14}, "window", r"--window must be at least 15 cells \(a training window holds at least 200"),
        ({"poses": 0}, "poses", "--poses must be at least 1"),
        ({"sigma": -1.0}, "sigma", "--sigma must be finite and above 0 cells"),
        ({"range_cells": math.inf}, "range_cells", "--range-cells must be finite"),
        ({"lr": 0.0}, "lr", "--lr must be finite and above 0"),
        ({"dilations": (1, 0)}, "dilations", "--dilations must be one or more whole numbers"),
        ({"channels": 257}, "channels", "--channels must be at most 256, got 257"),
        ({"dilations": (1, 17)}, "dilations", r"--dilations must be at most 16 layers of at most 16, got \(1, 17\)"),
        ({"dilations": (1,) * 17}, "dilations", "--dilations must be at most 16 layers"),
        ({"seed": -1}, "seed", "--seed must be a whole number of at least 0"),
        ({"pixel_size": 0.05}, "pixel_size", "--pixel-size needs --plan-files"),
        ({"range_m": 2.0, "range_cells": 30.0}, "range_m", "--range-cells or --range-m, not both"),
        ({"examples": 100_000, "window": 96}, "examples", r"take 29\.\d GiB, over the limit of 4 GiB"),
    ],
)
def test_bad_options_are_refused_naming_them(kw, option, match):
    with pytest.raises(GuideSettingsError, match=match) as e:
        small(**kw)
    assert e.value.option == option and isinstance(e.value, ValueError)


def test_a_range_in_metres_is_a_range_in_cells_of_005_m():
    s = GuideTrainingSettings(corpus=("ipa",), range_m=8.0)
    assert s.range_cells == pytest.approx(160.0)
    assert s.fingerprint() != GuideTrainingSettings(corpus=("ipa",)).fingerprint()
    assert "--range-m 8.0" in s.command("g.npz") and "--range-cells" not in s.command("g.npz")
    assert s.example_bytes == (600 + 60) * 96 * 96 * gs.BYTES_PER_CELL < gs.MAX_EXAMPLE_BYTES


def test_an_interrupted_training_resumes_from_its_checkpoint_bit_for_bit(tmp_path):
    """Stopped after 4 of 6 steps (as Ctrl-C stops it: past the first validation, so the validation-best
    weights ride in the checkpoint), the same call resumes to the uninterrupted run's artefact and history,
    then drops the checkpoint; a checkpoint of other settings is refused naming them, and fresh ignores it."""
    s = small(steps=6, eval_every=3)
    ref = tmp_path / "ref.npz"  # uninterrupted, here: the same torch threads as the resumed run
    ref_meta = train_corpus_guide(s, ref, progress=False).record
    out = tmp_path / "g.npz"
    r = train_corpus_guide(s, out, progress=False, stop_after=4)
    assert not r.finished and r.record is None and r.step == 4
    ckpt = gt.checkpoint_path(out)
    assert ckpt.exists() and not out.exists() and r.checkpoint == ckpt
    with pytest.raises(CheckpointError, match=r"settings that differ: lr\); rerun with its settings, or pass --fresh"):
        train_corpus_guide(dataclasses.replace(s, lr=0.01), out, progress=False)
    meta = train_corpus_guide(s, out, progress=False).record
    assert meta is not None and ref_meta is not None
    assert not ckpt.exists()
    assert _weights_equal(ref, out)
    hist = [json.loads(p.with_suffix(".json").read_text())["history"] for p in (ref, out)]
    assert hist[0] == hist[1] and meta["validation"] == ref_meta["validation"]
    assert not train_corpus_guide(s, out, progress=False, stop_after=2).finished and ckpt.exists()
    train_corpus_guide(dataclasses.replace(s, lr=0.01), out, progress=False, fresh=True)  # from scratch
    assert not ckpt.exists()
    ckpt.write_bytes(b"not a zip")
    with pytest.raises(CheckpointError, match="not a readable checkpoint"):
        train_corpus_guide(s, out, progress=False)


def _command_args(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="ogm-ppl")
    sub = p.add_subparsers(dest="command")
    command.add_parser(sub)
    return p.parse_args(argv)


def test_the_command_trains_on_a_folder_of_ones_own_plan_files(tmp_path, capsys):
    """``ogm-ppl train-guide --plan-files DIR``: the plans of other buildings (a PNG at 0.025 m pixels and a
    ROS map), every fifth one validating; the record names the files' digests and the command."""
    folder = write_plan_folder(tmp_path)
    out = tmp_path / "mine.npz"
    argv = ["train-guide", "--plan-files", str(folder), "--pixel-size", "0.025", *SMALL_FLAGS]
    args = _command_args([*argv, "--steps", "2", "--eval-every", "1", "--out", str(out)])
    assert args.command == "train-guide" and command.run(args) == 0
    said = capsys.readouterr()
    assert "ogm-ppl train-guide: kept step" in said.out and "files: 1 training plans, 1 validation plans" in said.err
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["corpus"] == "files" and side["training_plans"] == 1 and side["validation_plans"] == 1
    assert sorted(side["plan_files_sha256"]) == ["hall", "office"]
    assert side["plan_names_sha256"] == leakage.names_digest(["hall", "office"])
    assert side["provenance"]["command"].startswith(f"ogm-ppl train-guide --plan-files {folder} --pixel-size 0.025")
    assert [h["step"] for h in side["history"]] == [1, 2] and AmortisedGuide.load(out).trained_for["corpus"] == "files"
    # the settings the command made are the library's own
    want = small(corpus=(), plan_files=(folder,), pixel_size=0.025, steps=2, eval_every=1)
    assert command.settings_from_args(args) == want


def test_the_command_needs_an_output_and_names_bad_options(tmp_path, capsys):
    with pytest.raises(SystemExit):
        _command_args(["train-guide", "--corpus", "ipa"])  # --out FILE.npz or --ship
    assert "one of the arguments --out --ship is required" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        _command_args(["train-guide", "--corpus", "ipa", "--range-m", "4", "--range-cells", "80", "--out", "g.npz"])
    args = _command_args(["train-guide", "--corpus", "ipa", "--steps", "0", "--out", str(tmp_path / "g.npz")])
    with pytest.raises(GuideSettingsError, match="--steps must be at least 1"):
        command.run(args)
    args = _command_args(["train-guide", "--corpus", "ipa", "dungeon", "--ship"])
    assert command.shipped_path(command.settings_from_args(args)) == leakage.FITTED_DIR / "guide_ipa+dungeon.npz"
    with pytest.raises(ValueError, match=r"--out must name a \.npz file"):
        command.run(_command_args(["train-guide", "--corpus", "ipa", "--out", str(tmp_path / "g.pt")]))


def test_a_plan_file_source_needs_two_plans(tmp_path):
    from ogm_ppl.datasets.plan_files import PlanFileError

    folder = write_plan_folder(tmp_path)
    with pytest.raises(PlanFileError, match="one plan: a guide needs 2 or more"):
        ge.files_source([folder / "hall.yaml"])
    with pytest.raises(PlanFileError, match="pixel size"):
        ge.files_source([folder])  # the PNG has no scale


def test_the_script_still_trains_through_the_library(tmp_path):
    """``experiments/train_corpus_guide.py`` takes the command's options and gives the command's guide, bit for
    bit (both in a fresh interpreter: float32 training sums depend on the thread count a process runs with)."""
    out, ref = tmp_path / "script.npz", tmp_path / "lib.npz"
    argv = ["--corpus", "ipa", *SMALL_FLAGS, "--steps", "2", "--eval-every", "2", "--out", out, "--quiet"]
    r = run_script("train_corpus_guide.py", *argv)
    assert r.returncode == 0, r.stderr
    cmd = [sys.executable, "-m", "ogm_ppl", "train-guide", *map(str, argv[:-3]), "--out", str(ref), "--quiet"]
    c = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert c.returncode == 0, c.stderr
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["corpus"] == "ipa" and _weights_equal(out, ref)
    assert meta["provenance"]["command"].startswith("python experiments/train_corpus_guide.py --corpus ipa")
    bad = run_script("train_corpus_guide.py", "--corpus", "ipa", "--fov", "180")
    assert bad.returncode == 1 and "--fov applies to driven scans only" in bad.stderr


def test_ctrl_c_stops_at_the_end_of_the_step_with_a_checkpoint(tmp_path, monkeypatch):
    """SIGINT during a step: the step finishes, the checkpoint is written and the call returns unfinished; in a
    worker thread (no signal handler there) training runs as well."""
    import os
    import signal
    import threading

    real, calls = gt.batch, []

    def interrupting(exs, sym):
        calls.append(sym)
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGINT)
        return real(exs, sym)

    monkeypatch.setattr(gt, "batch", interrupting)
    out = tmp_path / "g.npz"
    before = signal.getsignal(signal.SIGINT)
    r = train_corpus_guide(small(steps=6, eval_every=3), out, progress=False)
    assert not r.finished and r.step == 2 and gt.checkpoint_path(out).exists()
    assert signal.getsignal(signal.SIGINT) is before  # the handler before is back
    monkeypatch.setattr(gt, "batch", real)
    done: list = []
    t = threading.Thread(
        target=lambda: done.append(train_corpus_guide(small(steps=2), tmp_path / "t.npz", progress=False))
    )
    t.start()
    t.join()
    assert done and done[0].finished


def test_ogm_ppl_train_guide_runs_and_reports_bad_options_in_one_line(tmp_path, capsys):
    """``ogm-ppl train-guide`` through the command line's entry point: 0 and the guide written; a bad option or
    a missing ``--out`` give one ``ogm-ppl: error:`` line and exit status 2."""
    from ogm_ppl.cli import COMMANDS, main

    assert COMMANDS["train-guide"] == "train_guide"
    out = tmp_path / "g.npz"
    argv = ["train-guide", "--corpus", "ipa", *SMALL_FLAGS, "--steps", "2", "--eval-every", "2", "--quiet"]
    assert main([*argv, "--out", str(out)]) == 0
    assert out.exists() and out.with_suffix(".json").exists() and not gt.checkpoint_path(out).exists()
    assert capsys.readouterr().err == ""  # --quiet
    assert main(["train-guide", "--corpus", "ipa", "--window", "0", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip() == "ogm-ppl: error: --window must be at least 1, got 0"
    assert main(["train-guide", "--corpus", "ipa"]) == 2
    assert "one of the arguments --out --ship is required" in capsys.readouterr().err
