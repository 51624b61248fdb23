"""The new floor-plan corpora by name: statistics and the corpus-stats command, the fit and calibrate commands'
corpus tables, the leakage checks across houseexpo and houseexpo-full, and (skipped where the shared data is
absent) a few real plans of each corpus."""

import json

import numpy as np
import pytest

from ogm_ppl.calibration import LeakageError, check_heldout
from ogm_ppl.datasets import floorplans as fp
from ogm_ppl.datasets.floorplans.stats import corpus_stats, plan_figure, wall_runs
from tests.datasets._corpus_fixtures import R2V_NAMES, write_houseexpo, write_r2v, write_schools

NEW = ("houseexpo-full", "r2v", "schools")


@pytest.fixture
def corpora(tmp_path, monkeypatch):
    """The three synthetic corpora under ``$OGM_PPL_FLOORPLANS`` (``tmp_path/corpora``)."""
    root = tmp_path / "corpora"
    write_houseexpo(root), write_r2v(root), write_schools(root)
    monkeypatch.setenv("OGM_PPL_FLOORPLANS", str(root))
    return root


def test_wall_runs_measure_walls_between_free_cells():
    occ = np.zeros((5, 9), bool)
    occ[:, 4:7] = True  # a wall 3 cells thick
    known = np.ones_like(occ)
    known[0] = False
    assert wall_runs(occ, known).tolist() == [3, 3, 3, 3]  # the rows; no column run has free at both ends
    known[:, 0] = False
    occ[:, 0] = True
    assert wall_runs(occ, known).tolist() == [3, 3, 3, 3]  # unknown ends do not count


@pytest.mark.parametrize("corpus", NEW)
def test_corpus_stats_and_figure(corpora, tmp_path, corpus):
    s = corpus_stats(corpus)
    n = len(fp.list_plans(corpus))
    assert s["plans"] == s["plans_in_corpus"] == n and sum(v["plans"] for v in s["splits"].values()) == n
    assert 0 < s["known_share"] < 1 and 0 < s["occupied_share"] < 0.5 and s["cells"] > 0
    assert s["wall_thickness_cells"]["percentiles"]["p50"] in (2, 3) and s["split_rule"] == fp.split_rule(corpus)
    json.dumps(s)
    if corpus == "r2v":
        assert s["r2v"]["scale_sources"] == {"openings": 4} and s["r2v"]["room_labels_inside_share"] == 1
    one = corpus_stats(corpus, split="train", limit=1)
    assert one["plans"] == 1 and one["splits"] == s["splits"]
    png = plan_figure(corpus, fp.list_plans(corpus)[:2], tmp_path / "f.png")
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_corpus_stats_command(corpora, tmp_path, capsys):
    from ogm_ppl.cli import main

    out = tmp_path / "out"
    assert main(["corpus-stats", "schools", "--out", str(out), "--figure-plans", "2", "--quiet"]) == 0
    doc = json.loads((out / "corpus_stats_schools.json").read_text())
    assert doc["corpus"] == "schools" and doc["plans"] == 3 and "commit" in doc["provenance"]
    assert (out / "corpus_schools.png").is_file()
    assert "schools: 3 plans of 2 buildings" in capsys.readouterr().out
    assert main(["corpus-stats", "atlantis", "--out", str(out)]) == 2


def test_the_fit_and_calibrate_commands_take_the_new_corpora(corpora):
    from ogm_ppl.calibration import CalibrationSettings
    from ogm_ppl.calibration.heldout import DEFAULT_TEST_CORPORA, TEST_CORPORA
    from ogm_ppl.cli import build_parser
    from ogm_ppl.learn import CORPORA, load_training_plans

    assert set(NEW) <= set(CORPORA) and set(NEW) <= set(TEST_CORPORA)
    assert DEFAULT_TEST_CORPORA == ("generated", "houseexpo", "ipa", "dungeon")  # what runs by default is unchanged
    assert CalibrationSettings().resolved().test == DEFAULT_TEST_CORPORA
    assert CalibrationSettings(test=("r2v",)).test == ("r2v",)
    args = build_parser().parse_args(["fit-prior", "tables", "--corpus", "houseexpo-full", "--out", "x"])
    assert args.corpus == "houseexpo-full"
    assert build_parser().parse_args(["calibrate", "--test", "schools", "r2v"]).test == ["schools", "r2v"]
    plans = load_training_plans("r2v")
    assert (
        plans.names
        == tuple(fp.training_plans("r2v"))
        == (R2V_NAMES[2],) + ((R2V_NAMES[3],) if fp.split_of("r2v", R2V_NAMES[3]) == "train" else ())
    )
    assert plans.source["split_rule"] == fp.split_rule("r2v")
    maps = list(plans.maps())
    assert maps[0].corpus == "r2v" and maps[0].known.all()  # read as the fits read plans: outside occupied


def test_usable_windows_of_a_new_corpus(corpora):
    from ogm_ppl.calibration.heldout import usable_windows

    got = usable_windows("schools", fp.list_plans("schools"), 2, 64)
    assert [t.plan for t in got] == ["Alpha1", "Alpha2"] and got[0].truth.shape == (64, 64)


def test_leakage_across_houseexpo_and_houseexpo_full():
    """A house is the same building in both corpora: a prior learned on one is not scored on its houses in the
    other; other corpora share no building with them."""
    with pytest.raises(LeakageError, match="houseexpo-full test map"):
        check_heldout("houseexpo-full", ["bb", "aa"], "houseexpo", train={"aa"})
    with pytest.raises(LeakageError, match="training set of the houseexpo-full tables"):
        check_heldout("houseexpo", ["aa"], "houseexpo-full", train={"aa"})
    check_heldout("houseexpo-full", ["bb"], "houseexpo", train={"aa"})
    check_heldout("r2v", ["aa"], "houseexpo-full", train={"aa"})  # another namespace
    check_heldout("schools", ["x"], "schools", train={"y"})


# -- the real corpora ------------------------------------------------------------------------------------------------
def _real(corpus: str) -> list[str]:
    try:
        return fp.list_plans(corpus)
    except fp.CorpusNotFoundError:
        pytest.skip(f"the {corpus} corpus is not in the shared data")


def test_real_houseexpo_full_keeps_the_subset_split_and_its_renderings():
    from ogm_ppl.calibration import training_set

    full, subset = _real("houseexpo-full"), _real("houseexpo")
    assert len(full) == 33717
    both = sorted(set(full) & set(subset))
    assert len(both) == 96
    test_full = set(fp.heldout_plans("houseexpo-full"))
    assert {n for n in both if fp.split_of("houseexpo", n) == "test"} <= test_full  # subset test houses stay test
    assert not training_set("houseexpo") & test_full  # no shipped prior's house is a test house here
    assert not set(fp.heldout_plans("houseexpo")) & set(fp.training_plans("houseexpo-full"))
    check_heldout("houseexpo-full", sorted(test_full)[:200], "houseexpo")
    for a in fp.iter_plans("houseexpo-full", both[:3], outside="unknown"):
        b = fp.load_plan("houseexpo", a.name, outside="unknown")
        assert a.shape == b.shape
        assert ((a.occupancy == b.occupancy) & (a.known == b.known)).mean() > 0.999


@pytest.mark.parametrize("corpus", NEW)
def test_real_plans_read(corpus):
    names = _real(corpus)
    assert len(names) == {"houseexpo-full": 33717, "r2v": 1279, "schools": 50}[corpus]
    picks = [names[i] for i in (0, len(names) // 2, -1)]
    for p in fp.iter_plans(corpus, picks, outside="unknown"):
        assert p.resolution == 0.05 and 0.3 < p.known.mean() < 0.95 and 0.02 < p.occupied_fraction < 0.3
        assert np.median(wall_runs(p.occupancy, p.known)) in (2, 3, 4)
    if corpus == "r2v":
        splits = [fp.split_of("r2v", n) for n in names]
        assert splits.count("val") == 36 and splits.count("test") >= 100
    if corpus == "schools":
        assert fp.split_of("schools", "Sabadell1") == fp.split_of("schools", "Sabadell3")


def test_real_r2v_scale_consistency():
    """On the real corpus the openings' scale agrees with the fixtures' to the documented 14 %."""
    from ogm_ppl.datasets.floorplans import r2v

    names = _real("r2v")
    plans = [r2v.read_plan(r2v.plan_path(n)) for n in names]
    c = r2v.scale_consistency(plans)
    assert c["plans"] > 1100 and 0.10 < c["sd_log_openings"] < 0.17
    assert 0.7 < c["median_toilet_m"] < 0.9 and 1.1 < c["median_bathtub_m"] < 1.5


def test_a_layout_named_by_a_houseexpo_full_id_is_a_corpus_plan(corpora, tmp_path):
    from ogm_ppl.datasets.plan_files import corpus_copy

    for d in ("houseexpo-subset100/png", "ipa-room-segmentation-maps/test_maps"):
        (corpora / d).mkdir(parents=True)
    mine = tmp_path / "mine"
    mine.mkdir()
    for name in ("0a1b", "zzzz"):
        (mine / f"{name}.json").write_text(json.dumps({"verts": [[0, 0], [3, 0], [3, 2], [0, 2]]}))
    assert corpus_copy(mine / "0a1b.json") == "the layout of the houseexpo-full corpus's plan 0a1b"
    assert corpus_copy(mine / "zzzz.json") is None
