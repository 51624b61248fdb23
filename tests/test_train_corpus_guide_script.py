"""experiments/train_corpus_guide.py on tiny settings: it trains on the tables' training plans only, records
them, keeps the validation-best step, and the calibration run scores the artefact (``guides``) or refuses one
whose record is not the tables' training set."""

import json
import math
import sys

import pytest
import torch

import ogm_ppl.calibration as cal
from ogm_ppl.calibration import leakage
from ogm_ppl.calibration import run as run_module
from ogm_ppl.cli.calibrate import build_parser, settings_from_args
from tests._scripts import load_experiment


@pytest.fixture(scope="module")
def mods():
    threads = torch.get_num_threads()
    tg = load_experiment("train_corpus_guide_script", "train_corpus_guide.py")
    yield tg, cal
    torch.set_num_threads(threads)
    sys.modules.pop("train_corpus_guide_script", None)


def _calibrate(argv: list[str]) -> cal.CalibrationResult:
    """The calibration run with the options of ``ogm-ppl calibrate``."""
    args = build_parser().parse_args(argv)
    return cal.calibrate(settings_from_args(args), args.out, progress=False)


SMALL = "--examples 6 --val 2 --window 40 --poses 2 --beams 45 --range-cells 30 --channels 4 --dilations 1 2 1".split()


@pytest.fixture(scope="module")
def artefact(mods, tmp_path_factory):
    tg, _ = mods
    out = tmp_path_factory.mktemp("guide") / "g.npz"
    meta = tg.main(["--corpus", "ipa", *SMALL, "--steps", "6", "--eval-every", "3", "--out", str(out)])
    return out, meta


def test_training_uses_the_tables_plans_and_records_them(mods, artefact):
    tg, _ = mods
    out, meta = artefact
    train, val = tg.split_plans("ipa")
    names = cal.training_set("ipa")
    assert set(train) | set(val) == names and not set(train) & set(val) and val == sorted(names)[::5]
    assert meta["plan_names_sha256"] == cal.names_digest(names) and meta["corpus"] == "ipa"
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


def test_the_kept_weights_reproduce_the_recorded_validation_loss(mods, artefact):
    """Rebuilding the validation set from the same seed and scoring the saved guide gives the recorded loss."""
    tg, _ = mods
    from ogm_ppl.inference.variational.amortised import AmortisedGuide

    out, meta = artefact
    args = tg.argparse.Namespace(poses=2, beams=45, range_cells=30.0, sigma=1.0, scan_whole_map=False, crops=8)
    _, val = tg.split_plans("ipa")
    exs = tg.build_set("ipa", val, 2, 40, args, 0 + 1, "validation")
    got = tg.losses(AmortisedGuide.load(out), exs)
    assert got["bits_per_unseen_cell"] == pytest.approx(meta["validation"]["bits_per_unseen_cell"], rel=1e-5)


def test_the_temperature_is_folded_into_the_logits(mods):
    tg, _ = mods
    from ogm_ppl.inference.variational.amortised import AmortisedGuide

    g = AmortisedGuide(channels=3, dilations=(1,), phase=(0, 0), seed=1)
    x = torch.randn(1, 7, 9, 9, dtype=torch.float32)
    before = g.net(x)[0].detach().clone()
    # the truth is sharper than the logits, so the temperature is below 1
    y = (torch.rand(9, 9, dtype=torch.float32) < torch.sigmoid(3 * before)).float()
    e = tg.Example(x=x[0], y=y, scored=torch.ones(9, 9, dtype=torch.bool), unseen=torch.ones(9, 9, dtype=torch.bool))
    t = tg.fit_temperature(g, [e])
    assert 0.25 <= t < 1
    torch.testing.assert_close(g.net(x)[0].detach(), before / t)


def test_a_symmetry_turns_features_and_truth_together(mods):
    tg, _ = mods
    x = torch.arange(2 * 3 * 4, dtype=torch.float32).reshape(2, 3, 4)
    y = x[0].clone()
    e = tg.Example(x=x, y=y, scored=y > 3, unseen=y > 7)
    for sym in range(8):
        bx, by, bs, bu = tg._batch([e], sym)
        assert torch.equal(bx[0, 0], by[0]) and torch.equal(bs[0], by[0] > 3) and torch.equal(bu[0], by[0] > 7)
    assert tg._batch([e], 1)[1].shape == (1, 4, 3) and torch.equal(tg._batch([e], 4)[1][0], y.flip(-1))


def test_calibration_scores_the_guide_and_refuses_another_record(mods, artefact, tmp_path, monkeypatch):
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


def test_a_whole_map_scene_gives_crops_of_one_scan(mods):
    """``--scan-whole-map``: one route through the whole map, its features cropped: each crop is the whole-map
    scene's own window (features, truth, unseen cells), not a scene of its own."""
    import numpy as np

    from ogm_ppl.datasets.mapgen import generate_map

    tg, _ = mods
    occ = generate_map("office", (90, 90), seed=5, border=4)
    plan = tg.Plan(occ, np.ones_like(occ), 0.05)
    args = tg.argparse.Namespace(poses=0, beams=90, range_cells=30.0, sigma=1.0, drive=None, plan_range_cells=None)
    exs = tg.scene_examples(plan, 40, 3, args, np.random.default_rng(0))
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
    names = list(tg.generated_maps())
    assert len(names) == 100 and names[0].startswith("seedstream:")


def test_a_guide_of_two_corpora_records_each_training_set(mods, tmp_path, monkeypatch):
    """``--corpus ipa dungeon``: one guide named ``ipa+dungeon``, windows from both corpora's training plans,
    each corpus's training set recorded; :func:`load_corpus_guide` checks every one and refuses a record that
    lacks one or names other plans; the calibration run checks the test plans against each corpus."""
    tg, _ = mods
    out = tmp_path / "g2.npz"
    meta = tg.main(["--corpus", "ipa", "dungeon", *SMALL, "--steps", "2", "--eval-every", "2", "--out", str(out)])
    assert meta["corpus"] == "ipa+dungeon" and "plan_names_sha256" not in meta
    for c in ("ipa", "dungeon"):
        assert meta["corpora"][c]["plan_names_sha256"] == cal.names_digest(cal.training_set(c))
        train, val = tg.split_plans(c)
        assert meta["corpora"][c]["training_plans"] == len(train) and meta["corpora"][c]["validation_plans"] == len(val)
    assert [tg._share(7, 2, i) for i in range(2)] == [4, 3]
    monkeypatch.setattr(leakage, "guide_path", lambda corpus, directory=None: out)
    assert cal.load_corpus_guide("ipa+dungeon").trained_for["corpus"] == "ipa+dungeon"
    with pytest.raises(cal.LeakageError, match="names corpus 'ipa\\+dungeon', not 'ipa'"):
        cal.load_corpus_guide("ipa")
    from ogm_ppl.inference.variational.amortised import AmortisedGuide

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
    """What the calibration run reads of a guide before it scores one: its weights (for the rows' digest) and
    ``symmetrize``."""

    symmetrize = False
    net = torch.nn.Linear(1, 1)


def test_calibration_checks_a_two_corpus_guide_against_each_corpus(mods, monkeypatch, tmp_path):
    """The leakage check runs for every corpus a guide was learned on: a test plan that is a training plan of
    either corpus is refused."""
    seen: list[tuple] = []
    monkeypatch.setattr(run_module, "check_heldout", lambda test, plans, train: seen.append((test, train)))
    monkeypatch.setattr(leakage, "load_corpus_guide", lambda c, directory=None: _FakeGuide())
    monkeypatch.setattr(run_module, "make_scene", lambda t, args: (_ for _ in ()).throw(SystemExit("stop")))
    with pytest.raises(SystemExit, match="stop"):
        _calibrate(
            "--test ipa --priors independent --guides ipa+dungeon --plans 1 --window 36 --no-figures --out".split()
            + [str(tmp_path)]
        )
    assert ("ipa", "ipa") in seen and ("ipa", "dungeon") in seen


def test_a_symmetrised_guide_row_loads_the_guide_symmetrised_and_checks_its_corpora(mods, monkeypatch, tmp_path):
    """``--guides C1+C2@sym``: the guide of C1+C2 with ``symmetrize`` on, its leakage checked per corpus."""
    seen: list[tuple] = []
    loaded: list = []

    def load(c, directory=None):
        loaded.append((c, _FakeGuide()))
        return loaded[-1][1]

    monkeypatch.setattr(run_module, "check_heldout", lambda test, plans, train: seen.append((test, train)))
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


def test_driven_scans_face_ahead_at_the_drawn_path_step(mods):
    """``--drive``: poses every ``S`` cells of the route's path (``S`` one of the listed steps), each scan
    ``--fov`` degrees ahead with beams ``360 / --beams`` apart; a denser drive reaches more cells."""
    import numpy as np

    from ogm_ppl import Grid, raycast
    from ogm_ppl.datasets import drive_route, plan_route
    from ogm_ppl.datasets.mapgen import generate_map

    tg, _ = mods
    occ = generate_map("office", (90, 90), seed=5, border=4)
    grid = Grid(occ.shape, 0.05)
    route = plan_route(occ, grid, max_range_cells=30, seed=1)
    args = tg.argparse.Namespace(beams=180, fov=180.0, range_cells=30.0, sigma=0.5, drive=[4.0])
    s = tg.driven_scans(occ, grid, route, args, np.random.default_rng(0))
    np.testing.assert_allclose(s.poses, drive_route(occ, grid, route, step_cells=4.0))
    assert s.beams_per_scan == 90
    np.testing.assert_allclose(np.degrees(np.asarray(s.angles).reshape(-1, 90)[0, [0, -1]]), [-89.0, 89.0])
    far = tg.argparse.Namespace(**{**vars(args), "drive": [40.0]})
    sparse = tg.driven_scans(occ, grid, route, far, np.random.default_rng(0))
    assert len(sparse.poses) < len(s.poses) / 5
    reached = [int(raycast(grid, x).reached().sum()) for x in (s, sparse)]
    assert reached[0] > reached[1]
    with pytest.raises(SystemExit, match="--drive needs --scan-whole-map"):
        tg.main(["--corpus", "ipa", "--drive", "10"])
    with pytest.raises(SystemExit, match="finite path steps"):
        tg.main(["--corpus", "ipa", "--scan-whole-map", "--poses", "0", "--drive", "10", "nan"])
    with pytest.raises(SystemExit, match="--fov applies to driven scans only"):
        tg.main(["--corpus", "ipa", "--fov", "180"])
    with pytest.raises(SystemExit, match="--plan-range-cells needs --scan-whole-map"):
        tg.main(["--corpus", "ipa", "--plan-range-cells", "75"])


def test_the_planner_range_sets_the_stops_not_the_scans(mods, monkeypatch):
    """``--plan-range-cells``: the route is planned for that range, the scans keep ``--range-cells``."""
    import importlib

    import numpy as np

    from ogm_ppl.datasets.mapgen import generate_map

    sas = importlib.import_module("ogm_ppl.datasets.stop_and_scan")  # the module, not the function of that name

    tg, _ = mods
    occ = generate_map("office", (120, 120), seed=5, border=4)
    plan = tg.Plan(occ, np.ones_like(occ), 0.05)
    seen = []
    real = sas.plan_route

    def spy(*a, **k):
        seen.append(k["max_range_cells"])
        return real(*a, **k)

    monkeypatch.setattr(sas, "plan_route", spy)
    for plan_range in (None, 20.0):
        args = tg.argparse.Namespace(
            poses=0, beams=90, range_cells=60.0, sigma=1.0, drive=None, plan_range_cells=plan_range
        )
        tg.scene_examples(plan, 40, 1, args, np.random.default_rng(0))
    assert seen == [60.0, 20.0]


def test_several_corpora_refuse_too_few_windows_to_share(mods):
    """Each corpus needs a training and a validation window: ``--val 1`` for two corpora is refused before any
    data are read, as is a corpus named twice."""
    tg, _ = mods
    with pytest.raises(SystemExit, match="at least one window"):
        tg.main(["--corpus", "ipa", "dungeon", "--examples", "6", "--val", "1"])
    with pytest.raises(SystemExit, match="names a corpus twice"):
        tg.main(["--corpus", "ipa", "ipa"])


def test_an_interrupted_training_resumes_from_its_checkpoint_bit_for_bit(mods, tmp_path):
    """Stopped after 4 of 6 steps (as Ctrl-C stops it: past the first validation, so the validation-best
    weights ride in the checkpoint), the same command resumes to the uninterrupted run's artefact and history,
    then drops the checkpoint; a checkpoint of other settings is refused naming them, and --fresh ignores it."""
    tg, _ = mods
    from ogm_ppl.inference.variational.amortised import AmortisedGuide

    ref = tmp_path / "ref.npz"  # uninterrupted, here: the same torch threads as the resumed run
    ref_meta = tg.main(["--corpus", "ipa", *SMALL, "--steps", "6", "--eval-every", "3", "--out", str(ref)])
    out = tmp_path / "g.npz"
    argv = ["--corpus", "ipa", *SMALL, "--steps", "6", "--eval-every", "3", "--out", str(out)]
    assert tg.main(argv, stop_after=4) is None
    ckpt = tg.checkpoint_path(out)
    assert ckpt.exists() and not out.exists()
    with pytest.raises(SystemExit, match=r"settings that differ: lr\); rerun with its settings, or pass --fresh"):
        tg.main([*argv, "--lr", "0.01"])
    meta = tg.main(argv)
    assert not ckpt.exists()
    a, b = AmortisedGuide.load(ref).net.state_dict(), AmortisedGuide.load(out).net.state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    hist = [json.loads(p.with_suffix(".json").read_text())["history"] for p in (ref, out)]
    assert hist[0] == hist[1] and meta["validation"] == ref_meta["validation"]
    assert tg.main(argv, stop_after=2) is None and ckpt.exists()
    tg.main([*argv, "--lr", "0.01", "--fresh"])  # another training in the same place, from scratch
    assert not ckpt.exists()
