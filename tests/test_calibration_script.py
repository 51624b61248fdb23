"""experiments/calibration.py on tiny settings: the matrix runs and writes what it promises, a rerun resumes,
the patch rule follows the compiled bundle, and a test map in a prior's training set is refused."""

import json
import math
import sys

import pytest
import torch

from ogm_ppl.calibration import heldout, leakage
from tests._scripts import load_experiment, write_plan_folder


@pytest.fixture(scope="module")
def cal():
    mod = load_experiment("calibration_experiment", "calibration.py")
    threads = torch.get_num_threads()
    yield mod
    torch.set_num_threads(threads)
    sys.modules.pop("calibration_experiment", None)


TINY = (
    "--test houseexpo generated --train houseexpo --priors independent mrf patch3 --plans 1 --window 36 "
    "--generated-shape 80 --poses 2 --beams 45 --range-cells 30 --sweeps 16 --burn 4"
).split()


def test_tiny_matrix_writes_rows_tables_figures_and_resumes(cal, tmp_path, monkeypatch):
    res = cal.main([*TINY, "--out", str(tmp_path)])
    rows = res["rows"]
    names = ["traditional OGM (p21)", "independent", "independent:houseexpo", "mrf:houseexpo", "patch3:houseexpo"]
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
            if name != "traditional OGM (p21)":
                assert 0 <= unseen["rhat_below"] <= 1 and unseen["rhat_cells"] == unseen["cells"]
                v = unseen["rhat_below_varying"]
                assert (0 <= v <= unseen["rhat_below"]) or math.isnan(v)  # frozen cells count as agreeing
        assert by["patch3:houseexpo", "unseen"]["patch"] == [3, 3] and by["mrf:houseexpo", "unseen"]["patch"] is None
        assert by["independent", "unseen"]["train"] == "none"
    doc = json.loads((tmp_path / "calibration.json").read_text())
    brief = json.loads((tmp_path / "calibration_summary.json").read_text())
    assert len(brief["summary"]) == 2 * 2 * len(names) and "reliability" not in brief["summary"][0]
    assert {"command", "commit", "machine"} <= set(doc["provenance"]) and doc["settings"]["sweeps"] == 16
    md = (tmp_path / "calibration.md").read_text()
    assert "| patch3:houseexpo |" in md and "Across corpora" in md
    assert {p.name for p in tmp_path.glob("*.png")} == {
        "matrix_unseen.png",
        "reliability_houseexpo.png",
        "reliability_generated.png",
        "bars_unseen.png",
        "bars_near.png",
    }

    def never(*a, **k):
        raise AssertionError("a resumed run recomputed a row it had")

    monkeypatch.setattr(cal, "run_prior", never)
    monkeypatch.setattr(cal, "run_ogm", never)
    again = cal.main([*TINY, "--out", str(tmp_path), "--no-figures"])
    assert len(again["rows"]) == len(rows)
    runs = json.loads((tmp_path / "calibration.json").read_text())["runs"]
    assert len(runs) == 2 and runs[0]["seconds"] == doc["runs"][0]["seconds"]
    with pytest.raises(SystemExit, match="settings differ in \\['sweeps'\\]"):
        cal.main([*TINY[:-4], "--sweeps", "17", "--burn", "4", "--out", str(tmp_path)])


def test_default_patch_follows_the_compiled_bundle(cal):
    from ogm_ppl.priors.named import prior_by_name

    shape = (12, 12)
    got = {k: cal.default_patch(prior_by_name(f"{k}:houseexpo", shape)) for k in ("mrf", "patch3", "border", "border1")}
    assert got == {"mrf": None, "patch3": (3, 3), "border": (3, 3), "border1": None}
    assert cal._patch_overrides(["border1=3x3", "patch3=1"]) == {"border1": (3, 3), "patch3": None}


def test_a_map_in_the_training_set_is_refused(cal):
    from ogm_ppl.datasets import floorplans as fp

    train = cal.training_set("houseexpo")
    assert train == set(fp.training_plans("houseexpo", limit=len(train)))
    held = fp.heldout_plans("houseexpo")
    cal.check_heldout("houseexpo", held, "houseexpo")  # the split is disjoint
    cal.check_heldout("ipa", fp.heldout_plans("ipa", exclude_buildings=tuple(fp.REAL_LOG_BUILDINGS)), "ipa")
    leaked = sorted(train)[0]
    with pytest.raises(cal.LeakageError, match="training set of the houseexpo tables"):
        cal.check_heldout("houseexpo", [held[0], leaked], "houseexpo")
    cal.check_heldout("houseexpo", [leaked], "ipa")  # another corpus's tables: no overlap by construction
    with pytest.raises(cal.LeakageError, match="share a building"):
        cal.check_heldout("ipa", ["office_a"], "ipa", train={"office_a_furnitures"})
    with pytest.raises(cal.LeakageError, match="real-log building"):
        cal.check_heldout("ipa", ["intel_map"], None)
    # generated: held-out maps are root seed streams, the tables counted spawned children
    gen = cal.training_set("generated")
    assert len(gen) == 100 and leakage._identity("generated", "office/seed0") not in gen
    cal.check_heldout("generated", [f"office/seed{cal.generated_seed(i)}" for i in range(4)], "generated")
    with pytest.raises(cal.LeakageError, match="generated"):
        cal.check_heldout(
            "generated", ["hall/seed7"], "generated", train={leakage._identity("generated", "hall/seed7")}
        )


def test_prior_names_cover_the_matrix_once(cal):
    got = cal.prior_names(["independent", "mrf", "border:ipa", "mrf"], ["houseexpo", "ipa"])
    assert got == [
        ("independent", None),
        ("independent:houseexpo", "houseexpo"),
        ("independent:ipa", "ipa"),
        ("mrf:houseexpo", "houseexpo"),
        ("mrf:ipa", "ipa"),
        ("border:ipa", "ipa"),
    ]
    assert math.isclose(cal.RHAT_THRESHOLD, 1.05)


def test_a_prior_over_the_support_limit_is_skipped(cal):
    import numpy as np

    from ogm_ppl.priors.named import prior_by_name

    truth = np.zeros((24, 24), dtype=bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    truth[12, :14] = True
    t = cal.TestMap("generated", "box", "box", truth, np.ones_like(truth), 0.05)
    args = cal.parse_args([*TINY, "--max-support", "100"])
    scene = cal.make_scene(t, args)
    assert cal.support(prior_by_name("patch3:houseexpo", (24, 24)), (3, 3)) == 512
    assert cal.support(prior_by_name("mrf:houseexpo", (24, 24)), None) == 2
    assert "512 configurations" in cal.run_prior(scene, "patch3:houseexpo", args)["skipped"]
    res = cal.run_prior(scene, "mrf:houseexpo", args)
    assert res["patch"] is None and len(res["seconds_per_chain"]) == 3
    assert res["scores"]["unseen"]["cells"] == res["rhat_cells"] == int(scene.masks["unseen"].sum())


def test_diagonal_scores_each_corpus_with_its_own_priors_only(cal, tmp_path):
    argv = (
        "--test houseexpo ipa --train houseexpo ipa --priors independent --diagonal --plans 1 --window 36 "
        "--poses 2 --beams 45 --range-cells 30 --sweeps 4 --burn 2 --no-figures"
    ).split()
    rows = cal.main([*argv, "--out", str(tmp_path)])["rows"]
    got = sorted({(r["test"], r["prior_name"]) for r in rows})
    assert got == [
        ("houseexpo", "independent"),
        ("houseexpo", "independent:houseexpo"),
        ("houseexpo", "traditional OGM (p21)"),
        ("ipa", "independent"),
        ("ipa", "independent:ipa"),
        ("ipa", "traditional OGM (p21)"),
    ]


def _box_scene(cal, args):
    import numpy as np

    truth = np.zeros((24, 24), dtype=bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    truth[12, :14] = True
    return cal.make_scene(cal.TestMap("generated", "box", "box", truth, np.ones_like(truth), 0.05), args)


def test_tempering_kernel_scores_the_cold_rung_of_its_ladder(cal, monkeypatch):
    from ogm_ppl.inference.mcmc.tempering import ParallelTempering

    args = cal.parse_args([*TINY, "--kernel", "tempering", "--rungs", "3", "--beta-min", "0.25", "--temper", "both"])
    built = []

    def spy(model, patch, init, a):
        kernel = cal._tempering(model, patch, init, a)
        built.append((patch, kernel))
        return kernel

    monkeypatch.setitem(cal.KERNELS, "tempering", spy)
    scene = _box_scene(cal, args)
    for name, patch in (("mrf:houseexpo", None), ("patch3:houseexpo", (3, 3))):
        built.clear()
        res = cal.run_prior(scene, name, args)
        assert len(built) == len(cal.STARTS) == len(res["seconds_per_chain"])
        for p, kernel in built:
            assert p == patch and isinstance(kernel, ParallelTempering)
            assert list(kernel.betas) == pytest.approx([1.0, 0.5, 0.25]) and kernel.temper == "both"
        unseen = res["scores"]["unseen"]
        assert unseen["cells"] == res["rhat_cells"] == int(scene.masks["unseen"].sum()) and unseen["nll_bits"] > 0
    with pytest.raises(SystemExit):
        cal.parse_args([*TINY, "--kernel", "tempering", "--beta-min", "1.5"])
    with pytest.raises(SystemExit):
        cal.parse_args([*TINY, "--kernel", "tempering", "--rungs", "0"])


def test_tempering_settings_are_recorded_only_with_its_kernel(cal, tmp_path):
    argv = [*TINY[:2], "--train", "houseexpo", "--priors", "independent", *TINY[9:], "--no-figures"]

    def settings(name, *extra):
        cal.main([*argv, *extra, "--out", str(tmp_path / name)])
        return json.loads((tmp_path / name / "calibration.json").read_text())["settings"]

    assert not {"rungs", "beta_min", "temper"} & set(settings("gibbs"))
    got = settings("tempering", "--kernel", "tempering", "--rungs", "2")
    assert got["kernel"] == "tempering" and got["rungs"] == 2 and got["temper"] == "prior"


def test_a_tempered_kind_without_a_fitted_exponent_is_skipped(cal):
    from ogm_ppl.priors.named import load_temper_params

    assert "patch5" not in load_temper_params("ipa").beta
    args = cal.parse_args(TINY)
    res = cal.run_prior(_box_scene(cal, args), "patch5:ipa@cal", args)
    assert "no tempering exponent fitted for patch5 on ipa" in res["skipped"]


def test_a_bias_file_runs_each_named_prior_biased_beside_it(cal, tmp_path):
    """``--bias-file``: the priors it names run again as ``NAME+bias``. A zero bias is the prior itself (the same
    chain from the same seed, so the same scores); a bias of +3 raises the mean marginal of the unseen cells; the
    biases are settings a resume must share; a malformed file is refused naming it."""
    argv = ["--test", "houseexpo", "--train", "houseexpo", "--priors", "patch3", *TINY[9:], "--no-figures"]
    bias = tmp_path / "bias.json"
    bias.write_text(json.dumps({"format": "ogm_ppl.prior_bias", "bias": {"patch3:houseexpo": 0.0}}))
    rows = cal.main([*argv, "--bias-file", str(bias), "--out", str(tmp_path / "zero")])["rows"]
    by = {(r["prior_name"], r["mask"]): r for r in rows}
    assert by["patch3:houseexpo+bias", "unseen"]["prior"] == "patch3+bias"
    for mask in ("unseen", "near"):
        a, b = by["patch3:houseexpo", mask], by["patch3:houseexpo+bias", mask]
        assert (a["nll_bits"], a["auc"], a["rhat_below"]) == (b["nll_bits"], b["auc"], b["rhat_below"])
    bias.write_text(json.dumps({"format": "ogm_ppl.prior_bias", "bias": {"patch3:houseexpo": 3.0}}))
    with pytest.raises(SystemExit, match="settings differ in \\['bias'\\]"):
        cal.main([*argv, "--bias-file", str(bias), "--out", str(tmp_path / "zero")])
    rows = cal.main([*argv, "--bias-file", str(bias), "--out", str(tmp_path / "three")])["rows"]
    occ = {r["prior_name"]: r for r in rows if r["mask"] == "unseen"}
    mean_q = {k: sum(r["reliability"]["sum_q"]) / sum(r["reliability"]["count"]) for k, r in occ.items()}
    assert mean_q["patch3:houseexpo+bias"] > mean_q["patch3:houseexpo"] + 0.2  # +3 log-odds fills the unseen cells
    bias.write_text('{"format": "ogm_ppl.prior_bias", "bias": {"patch3:houseexpo": "high"}}')
    with pytest.raises(SystemExit, match=f"{bias}: not a bias file"):
        cal.main([*argv, "--bias-file", str(bias), "--out", str(tmp_path / "bad")])


PLAN_RUN = (
    "--train houseexpo --priors independent patch3 --diagonal --plans 5 --window 36 --poses 2 --beams 45 "
    "--range-cells 30 --sweeps 8 --burn 2 --no-figures --plan-set mine --pixel-size 0.025"
).split()


def test_plan_files_are_one_more_test_set_scored_with_every_prior(cal, tmp_path):
    d = write_plan_folder(tmp_path)
    res = cal.main([*PLAN_RUN, "--plan-files", str(d), "--out", str(tmp_path / "out")])
    rows = res["rows"]
    assert {r["test"] for r in rows} == {"mine"}  # no corpus runs unless --test names one
    assert sorted({r["plan"].split("@")[0] for r in rows}) == ["hall", "office"]
    # --diagonal limits the corpora's own priors; a plan set has none, so every prior runs on it
    assert {r["prior_name"] for r in rows} == {
        "traditional OGM (p21)",
        "independent",
        "independent:houseexpo",
        "patch3:houseexpo",
        "guide:houseexpo+ipa@sym",  # without --guides, the floor-plan guide
    }
    for r in rows:
        assert r["nll_bits"] > 0 and 0 < r["cells"] <= 36 * 36
    md = (tmp_path / "out" / "calibration.md").read_text()
    assert "**mine**, unseen cells (2 maps)" in md and "| patch3:houseexpo |" in md.split("**mine**, near")[0]
    settings = json.loads((tmp_path / "out" / "calibration.json").read_text())["settings"]
    assert settings["plan_files"] == [str(d)] and settings["plan_set"] == "mine" and settings["test"] == []
    # the same maps as the plan reader gives, cropped as the corpora's are
    maps = cal.plan_file_maps([d], 5, 36, 0.025, "mine")
    assert [t.corpus for t in maps] == ["mine", "mine"] and all(t.truth.shape == (36, 36) for t in maps)
    assert [t.name for t in cal.plan_file_maps([d], None, 36, 0.025)] == [t.name for t in maps]
    assert len(cal.plan_file_maps([d], 1, 36, 0.025)) == 1


def test_runs_without_plan_files_keep_their_settings(cal, tmp_path):
    argv = "--test generated --train houseexpo --priors independent --plans 1 --window 36 --quick --no-figures"
    cal.main([*argv.split(), "--out", str(tmp_path)])
    settings = json.loads((tmp_path / "calibration.json").read_text())["settings"]
    assert not {"plan_files", "plan_set", "pixel_size"} & set(settings)


def test_plan_file_arguments_are_checked(cal):
    with pytest.raises(SystemExit):
        cal.parse_args(["--plan-files", "x", "--plan-set", "generated"])  # a corpus's name
    with pytest.raises(SystemExit):
        cal.parse_args(["--plan-files", "x", "--plan-set", "a b"])
    with pytest.raises(SystemExit):
        cal.parse_args(["--pixel-size", "0.05"])  # without plan files
    assert cal.parse_args(["--plan-files", "x"]).test == [] and cal.parse_args([]).test == list(cal.TEST_CORPORA)
    args = cal.parse_args(["--plan-files", "x"])  # no --plans: 2 maps a corpus, every plan of the plan set
    assert (args.plans, args.plan_limit) == (2, None)
    assert args.guides == [cal.PLAN_FILES_GUIDE] and cal.parse_args([]).guides == []  # the floor-plan guide runs
    assert args.priors == list(cal.PLAN_FILES_PRIORS)  # and a few priors, not every kind
    assert len(cal.parse_args(["--plan-files", "x", "--test", "ipa"]).priors) > len(cal.PLAN_FILES_PRIORS)
    assert cal.parse_args(["--plan-files", "x", "--guides"]).guides == []
    assert cal.parse_args(["--plan-files", "x", "--plans", "3"]).plan_limit == 3


def test_a_corpus_plan_given_as_a_file_is_refused(cal, tmp_path):
    from ogm_ppl.datasets import floorplans as fp

    root = fp.floorplan_root()
    png = sorted((root / "houseexpo-subset100" / "png").glob("*.png"))
    if not png:
        pytest.skip("the HouseExpo corpus is not beside the repository")
    with pytest.raises(cal.LeakageError, match="a plan of the floor-plan corpora"):
        cal.check_plan_files([png[0]])
    (tmp_path / "copy.png").write_bytes(png[0].read_bytes())
    with pytest.raises(cal.LeakageError, match="the same bytes as the corpus plan"):
        cal.check_plan_files([tmp_path / "copy.png"])
    import numpy as np
    from PIL import Image

    px = np.asarray(Image.open(png[0]).convert("L")).copy()
    px[30, 30] = 255 - px[30, 30]  # touched up, turned and saved anew: other bytes, the same plan
    Image.fromarray(np.rot90(px)).save(tmp_path / "touched.png")
    with pytest.raises(cal.LeakageError, match=r"its free space overlaps the houseexpo plan"):
        cal.check_plan_files([tmp_path / "touched.png"])
    layout = tmp_path / f"{png[0].stem}.json"  # a HouseExpo layout under a corpus plan's id
    layout.write_text('{"verts": [[0, 0], [4, 0], [4, 3], [0, 3]]}')
    with pytest.raises(cal.LeakageError, match="the layout of the houseexpo corpus's plan"):
        cal.check_plan_files([layout])
    from ogm_ppl.datasets.plan_files import plan_files

    cal.check_plan_files(plan_files([write_plan_folder(tmp_path)]))  # plans of no corpus pass


def test_cells_a_plan_does_not_know_are_walls_to_the_sensor_and_never_scored(cal, tmp_path):
    """A map built from a log: a room seen whole, a side room nobody entered (unknown). With
    ``--plan-outside unknown`` the unknown cells stay unknown: stops never stand in them, no ray crosses them,
    and no mask scores them; by default they are occupied and scored, as the corpora's exteriors are."""
    import numpy as np

    from ogm_ppl import Grid
    from ogm_ppl.rosmap import save_ros_map

    p = np.ones((80, 80))
    p[10:70, 10:45] = 0.0  # the room
    p[30:36, 45:47] = 0.0  # a doorway
    unknown = np.zeros(p.shape, bool)
    unknown[20:60, 47:70] = True  # the room beyond it, never seen
    save_ros_map(tmp_path / "log.yaml", p[::-1].ravel(), Grid(p.shape, resolution=0.05), unknown=unknown[::-1].ravel())
    args = cal.parse_args("--plan-files x --poses 2 --beams 45 --range-cells 30".split())
    (t,) = cal.plan_file_maps([tmp_path / "log.yaml"], 1, 96, None, outside="unknown")
    assert not t.known.all() and not t.truth[~t.known].any()
    scene = cal.make_scene(t, args)
    for mask in scene.masks.values():
        assert not (mask & ~t.known.ravel()).any()
    from scipy import ndimage

    reached = scene.rays.reached().reshape(t.truth.shape)
    deep = ~ndimage.binary_dilation(t.known, structure=np.ones((3, 3), bool))  # unknown, no known neighbour
    assert deep.any() and (reached & ~t.known).any()  # rays end on the unknown cells next to the room ...
    assert not (reached & deep).any()  # ... as on a wall: none goes deeper
    (t_occ,) = cal.plan_file_maps([tmp_path / "log.yaml"], 1, 96, None)
    assert t_occ.known.all() and t_occ.truth[~t.known].all()
    np.testing.assert_array_equal(t_occ.truth, t.truth | ~t.known)
    with pytest.raises(SystemExit):
        cal.parse_args(["--plan-outside", "unknown"])  # without plan files


def test_a_changed_plan_file_refuses_to_resume_and_bad_files_exit_cleanly(cal, tmp_path):
    import numpy as np
    from PIL import Image

    from tests._scripts import write_plan_folder

    d = write_plan_folder(tmp_path)
    argv = [*PLAN_RUN, "--plan-files", str(d), "--out", str(tmp_path / "out")]
    argv[argv.index("--priors") + 2] = "independent"  # independent only: two priors are enough here
    cal.main(argv)
    cal.main(argv)  # unchanged files: resumes, nothing to run
    px = np.asarray(Image.open(d / "office.png")).copy()
    px[40:44, 40:120] = 0  # a wall added to the plan
    Image.fromarray(px).save(d / "office.png")
    with pytest.raises(SystemExit, match="settings differ in \\['plan_digests'\\]"):
        cal.main(argv)
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "junk.png").write_bytes(b"no image")
    with pytest.raises(SystemExit, match=r"calibration\.py: .*junk\.png: unreadable image"):
        cal.main([*PLAN_RUN, "--plan-files", str(tmp_path / "bad"), "--out", str(tmp_path / "out2")])
    (tmp_path / "bad" / "walls.json").write_text('{"verts": [[0, 0], [4, 0]]')  # cut short
    (tmp_path / "bad" / "room.png").write_bytes((d / "office.png").read_bytes())  # a good plan among them
    with pytest.raises(SystemExit) as e:  # every bad file is named, one a line
        cal.main([*PLAN_RUN, "--plan-files", str(tmp_path / "bad"), "--out", str(tmp_path / "out2")])
    lines = str(e.value).splitlines()
    assert len(lines) == 2 and "junk.png: unreadable image" in lines[0] and "walls.json: " in lines[1]
    errors = [cal.PlanFileError(f"f{i}", "wrong") for i in range(3)]
    assert str(heldout._every_error(errors)) == "f0: wrong\nf1: wrong\nf2: wrong"
    for bad in (["--plan-set", "IPA"], ["--plan-set", "none"], ["--sweeps", "3"], ["--plans", "0"]):
        with pytest.raises(SystemExit):
            cal.parse_args(["--plan-files", "x", *bad])


def test_bar_labels_drop_the_test_corpus_unless_two_would_read_alike(cal):
    names = ["independent", "independent:ipa", "patch3:ipa", "guide:houseexpo"]
    assert cal._labels(names, "ipa") == ["independent", "independent:ipa", "patch3", "guide:houseexpo"]


def test_a_prior_of_ones_own_runs_once_and_reruns_when_it_changes(cal, tmp_path, monkeypatch):
    """A registered kind named without a corpus runs once (trained on ``own``); a rerun computes again the rows
    of a prior that changed since (and only those); an unknown name stops the run before any work."""
    from ogm_ppl.priors import named

    from .priors.toy_checkerboard import KIND, CheckerboardPrior

    small = ["--test", "generated", "--train", "houseexpo", "--priors", KIND, "independent", *TINY[8:]]
    assert cal.prior_names([KIND, f"{KIND}:ipa"], ["houseexpo"]) == [(KIND, "own"), (f"{KIND}:ipa", "ipa")]
    first = cal.main([*small, "--out", str(tmp_path), "--no-figures"])["rows"]
    mine = [r for r in first if r["prior_name"] == KIND]
    assert len(mine) == 2 and {r["train"] for r in mine} == {"own"} and mine[0]["prior"] == KIND
    assert f"| {KIND} |" in (tmp_path / "calibration.md").read_text()  # in the test corpus's own table
    calls = []
    real = cal.run_prior
    monkeypatch.setattr(cal, "run_prior", lambda scene, name, *a, **k: calls.append(name) or real(scene, name, *a, **k))
    monkeypatch.setitem(named._FACTORIES, KIND, lambda shape, tables: CheckerboardPrior(shape, beta=2.0))
    again = cal.main([*small, "--out", str(tmp_path), "--no-figures"])["rows"]
    assert calls == [KIND] and len(again) == len(first)
    assert [r["nll_bits"] for r in again if r["prior_name"] == KIND] != [r["nll_bits"] for r in mine]

    def never(*a, **k):
        raise AssertionError("work started before the prior names were checked")

    monkeypatch.setattr(cal, "run_ogm", never)
    with pytest.raises(SystemExit, match="unknown prior kind 'no_such_kind'"):
        cal.main([*small, "--priors", "no_such_kind", "--out", str(tmp_path / "x")])
    assert not (tmp_path / "x").exists()  # refused before anything was made
    (tmp_path / "file").write_text("x")
    with pytest.raises(SystemExit, match=r"--out .*exists and is not a folder"):
        cal.main([*small, "--out", str(tmp_path / "file")])
