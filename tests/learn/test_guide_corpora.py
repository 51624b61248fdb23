"""Corpus guides on every corpus the library reads (``train-guide --corpus houseexpo-full r2v schools``):
``--sample N --sample-seed S`` draws a stated random subset of each corpus's training split, ``--name`` names a
guide of several corpora, the record states split, sample and command, and the leakage checks rebuild each
guide's training maps from its record (tiny settings: a few windows, two steps)."""

import json

import pytest

from ogm_ppl.calibration import leakage
from ogm_ppl.calibration import run as run_module
from ogm_ppl.cli import build_parser
from ogm_ppl.cli import train_guide as command
from ogm_ppl.datasets import floorplans as fp
from ogm_ppl.learn import GuideTrainingSettings, train_corpus_guide
from ogm_ppl.learn import guide_examples as ge
from ogm_ppl.learn import guide_settings as gs

TINY = dict(examples=4, val=4, window=40, poses=2, beams=45, range_cells=30.0, channels=4, dilations=(1, 2, 1))


def test_every_corpus_the_library_reads_is_a_guide_corpus():
    assert set(gs.CORPORA) == set(leakage.GUIDE_CORPORA) == {*fp.CORPORA, "generated"}
    args = build_parser().parse_args(
        "train-guide --corpus houseexpo-full r2v schools ipa --sample 300 --sample-seed 2 --name real --ship".split()
    )
    s = command.settings_from_args(args)
    assert s.corpus == ("houseexpo-full", "r2v", "schools", "ipa") and (s.sample, s.sample_seed) == (300, 2)
    assert s.label == "real" and command.shipped_path(s) == leakage.FITTED_DIR / "guide_real.npz"
    assert GuideTrainingSettings(corpus=("r2v", "schools")).label == "r2v+schools"
    assert GuideTrainingSettings(corpus=("r2v",), name="r2v").label == "r2v"  # its own corpus's name: allowed
    cmd = s.command(None, ship=True)
    assert "--sample 300 --sample-seed 2 --name real" in cmd and cmd.endswith("--ship")


def test_a_sample_is_a_stated_random_subset_of_the_training_split():
    """``guide_plans(c, N, S)``: ``min(N, n)`` of the ``n`` training plans (real-log buildings left out), nested
    for one seed, another subset for another seed, no held-out plan; no sample: the tables' training set."""
    split = fp.training_plans("schools")
    names, rec = leakage.guide_plans("schools", 10, 0)
    assert len(names) == 10 and set(names) <= set(split) and names == sorted(names)
    assert rec["split"] == "train" and rec["sample"]["random"] == 10 and rec["sample"]["of"] == len(split)
    assert set(leakage.guide_plans("schools", 5, 0)[0]) <= set(names)
    assert leakage.guide_plans("schools", 10, 1)[0] != names
    every, rec = leakage.guide_plans("schools", 10_000, 0)
    assert every == sorted(split) and rec["sample"]["random"] == len(split)
    held = set(fp.heldout_plans("schools"))
    assert not held & set(every) and not {fp.building_of("schools", n) for n in held} & {
        fp.building_of("schools", n) for n in every
    }
    tables, rec = leakage.guide_plans("ipa")
    assert set(tables) == leakage.training_set("ipa") and rec["sample"] is None
    with pytest.raises(ValueError, match="unknown corpus 'atlantis'"):
        leakage.guide_plans("atlantis")
    with pytest.raises(ValueError, match="at least 1"):
        leakage.guide_plans("schools", 0)


@pytest.fixture(scope="module")
def named(tmp_path_factory):
    """A guide named ``tiny`` learned on a random 6 of R2V's and of the schools' training plans."""
    out = tmp_path_factory.mktemp("named") / "guide_tiny.npz"
    s = GuideTrainingSettings(corpus=("r2v", "schools"), sample=6, sample_seed=3, name="tiny", steps=2, **TINY)
    r = train_corpus_guide(s, out, progress=False)
    assert r.finished and r.record is not None
    return out, r.record


def test_a_named_guide_records_split_sample_and_command(named):
    out, meta = named
    side = json.loads(out.with_suffix(".json").read_text())
    assert meta["corpus"] == side["corpus"] == "tiny" and sorted(meta["corpora"]) == ["r2v", "schools"]
    for c in ("r2v", "schools"):
        rec = meta["corpora"][c]
        names, _ = leakage.guide_plans(c, 6, 3)
        assert rec["split"] == "train" and rec["sample"]["random"] == 6 and rec["sample"]["seed"] == 3
        assert rec["plan_names_sha256"] == leakage.names_digest(names)
        assert (rec["training_plans"], rec["validation_plans"]) == (4, 2)  # every fifth of 6 validates
    cmd = side["provenance"]["command"]
    assert cmd.startswith("ogm-ppl train-guide --corpus r2v schools --sample 6 --sample-seed 3 --name tiny")


def test_a_named_guide_loads_only_with_the_training_maps_its_record_names(named, tmp_path):
    out, meta = named
    g = leakage.load_corpus_guide("tiny", directory=out.parent)
    sets = leakage.guide_training_sets("tiny", g.trained_for)
    assert sets == {c: set(leakage.guide_plans(c, 6, 3)[0]) for c in ("r2v", "schools")}
    with pytest.raises(leakage.LeakageError, match="names corpus 'tiny', not 'real'"):
        leakage.guide_training_sets("real", meta)
    bad = json.loads(json.dumps(meta))
    bad["corpora"]["schools"]["sample"]["seed"] = 4  # another sample than the plans it names
    with pytest.raises(leakage.LeakageError, match=r"record of schools .* not the random sample"):
        leakage.guide_training_sets("tiny", bad)
    bad["corpora"]["schools"]["sample"] = {"random": 6, "seed": 3, "of": 38}  # the split it sampled changed
    with pytest.raises(leakage.LeakageError, match="sampled 6 of 38 training plans; the training split now holds 39"):
        leakage.guide_training_sets("tiny", bad)
    del bad["corpora"]["schools"]["sample"]["seed"]
    with pytest.raises(leakage.LeakageError, match="malformed sample"):
        leakage.guide_training_sets("tiny", bad)
    with pytest.raises(leakage.LeakageError, match="does not list the corpora"):
        leakage.guide_training_sets("tiny", {**meta, "corpora": {"atlantis": {}}})
    g.save(tmp_path / "guide_tiny.npz", {**meta, "corpora": {"schools": meta["corpora"]["schools"]}})
    assert leakage.load_corpus_guide("tiny", directory=tmp_path).trained_for["corpus"] == "tiny"  # one corpus: fine
    g.save(tmp_path / "guide_r2v+schools.npz", {**meta, "corpus": "r2v+schools"})
    assert leakage.load_corpus_guide("r2v+schools", directory=tmp_path)  # the joined name of the same corpora


def test_the_calibration_checks_a_named_guide_against_every_corpus_it_names(named, monkeypatch, tmp_path):
    """``--guides tiny``: each test set is checked against the very training maps of R2V and of the schools
    that the guide's record names (not the tables' sets), before anything runs."""
    from ogm_ppl.calibration import calibrate
    from ogm_ppl.cli.calibrate import settings_from_args

    out, _ = named
    seen: dict = {}
    monkeypatch.setattr(run_module, "check_heldout", lambda test, plans, c, train=None: seen.setdefault(c, train))
    monkeypatch.setattr(run_module, "make_scene", lambda t, args: (_ for _ in ()).throw(SystemExit("stop")))
    argv = "calibrate --test schools --priors independent --guides tiny --plans 1 --window 36 --no-figures".split()
    args = build_parser().parse_args([*argv, "--guide-dir", str(out.parent), "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match="stop"):
        calibrate(settings_from_args(args), args.out, progress=False)
    assert seen["r2v"] == set(leakage.guide_plans("r2v", 6, 3)[0])
    assert seen["schools"] == set(leakage.guide_plans("schools", 6, 3)[0])


def test_houseexpo_full_plans_are_read_from_one_pass_over_the_file(monkeypatch):
    """The guide's ``houseexpo-full`` source reads the outlines of all its plans once, then rasterises each plan
    asked for as ``load_plan`` does."""
    from ogm_ppl.datasets.floorplans import houseexpo_full

    passes = []
    real = houseexpo_full.records

    def counting(names, root=None):
        passes.append(len(list(names)))
        return real(names, root)

    monkeypatch.setattr(houseexpo_full, "records", counting)
    src = ge.corpus_source("houseexpo-full", sample=3, seed=0)
    assert len(src.names) == 3 and src.record["sample"]["of"] == len(fp.training_plans("houseexpo-full"))
    maps = [src.load(n) for n in src.names]
    assert passes == [3]
    ref = fp.load_plan("houseexpo-full", src.names[1])
    assert (maps[1].occupancy == ref.occupancy).all() and (maps[1].known == ref.known).all()
    assert maps[1].resolution == ref.resolution == 0.05
