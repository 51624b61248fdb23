"""ogm_ppl.calibration.leakage: a test map in a prior's training set (or of a building in it, or of a real log's
building) is refused."""

import pytest

from ogm_ppl.calibration import LeakageError, check_heldout, generated_seed, leakage, training_set


def test_a_map_in_the_training_set_is_refused():
    from ogm_ppl.datasets import floorplans as fp

    train = training_set("houseexpo")
    assert train == set(fp.training_plans("houseexpo", limit=len(train)))
    held = fp.heldout_plans("houseexpo")
    check_heldout("houseexpo", held, "houseexpo")  # the split is disjoint
    check_heldout("ipa", fp.heldout_plans("ipa", exclude_buildings=tuple(fp.REAL_LOG_BUILDINGS)), "ipa")
    leaked = sorted(train)[0]
    with pytest.raises(LeakageError, match="training set of the houseexpo tables"):
        check_heldout("houseexpo", [held[0], leaked], "houseexpo")
    check_heldout("houseexpo", [leaked], "ipa")  # another corpus's tables: no overlap by construction
    with pytest.raises(LeakageError, match="share a building"):
        check_heldout("ipa", ["office_a"], "ipa", train={"office_a_furnitures"})
    with pytest.raises(LeakageError, match="real-log building"):
        check_heldout("ipa", ["intel_map"], None)
    # generated: held-out maps are root seed streams, the tables counted spawned children
    gen = training_set("generated")
    assert len(gen) == 100 and leakage._identity("generated", "office/seed0") not in gen
    check_heldout("generated", [f"office/seed{generated_seed(i)}" for i in range(4)], "generated")
    with pytest.raises(LeakageError, match="generated"):
        check_heldout("generated", ["hall/seed7"], "generated", train={leakage._identity("generated", "hall/seed7")})


def test_no_shipped_prior_was_trained_on_a_held_out_building_of_any_corpus():
    """Every shipped table set of a floor-plan corpus (a random sample included) against the whole held-out split
    of every floor-plan corpus: the check that runs before any scoring passes (skipped where the data is absent)."""
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.priors.tables import available_tables

    for test in fp.CORPORA:
        try:
            held = fp.heldout_plans(test, exclude_buildings=tuple(fp.REAL_LOG_BUILDINGS))
        except fp.CorpusNotFoundError:
            continue
        for train in (c for c in available_tables() if c != "generated"):
            check_heldout(test, held, train)


def test_no_shipped_guide_was_trained_on_a_held_out_building_of_any_corpus():
    """Every shipped corpus guide's training maps, rebuilt from its record (the tables' plans or a random sample
    of a training split, each checked against the recorded digest), against the whole held-out split of every
    floor-plan corpus (skipped where the data is absent); and a held-out plan slipped into a guide's training
    set is refused."""
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.inference.variational.amortised import AmortisedGuide
    from ogm_ppl.priors.tables import FITTED_DIR

    sets = {}
    for path in sorted(FITTED_DIR.glob("guide_*.npz")):
        if path.name.endswith(".ckpt.npz"):
            continue  # a training's checkpoint beside the guides, not a guide
        name = path.stem.removeprefix("guide_")
        meta = AmortisedGuide.load(path).trained_for
        if meta.get("kind") != "ogm_ppl.corpus_guide":
            continue  # the Table 6.4 guide of the generated maps, trained before corpus guides had records
        try:
            sets[name] = leakage.guide_training_sets(name, meta, path)
        except fp.CorpusNotFoundError:
            continue
    assert sets, "no shipped corpus guide checked"
    for test in fp.CORPORA:
        try:
            held = fp.heldout_plans(test, exclude_buildings=tuple(fp.REAL_LOG_BUILDINGS))
        except fp.CorpusNotFoundError:
            continue
        for per_corpus in sets.values():
            for corpus, train in per_corpus.items():
                check_heldout(test, held, corpus, train)
    held = fp.heldout_plans("schools")
    with pytest.raises(LeakageError, match="share a building"):
        check_heldout("schools", held[:1], "schools", train={*leakage.guide_plans("schools", 5)[0], held[0]})


def test_a_fixed_validation_set_is_drawn_apart_from_every_sample_it_serves():
    """``guide_split(c, N, S, M, after=K)``: the training plans are ``guide_plans(c, N, S)``'s, the ``M``
    validation plans are the same for every ``N`` up to ``K`` and in none of their samples, both within the
    training split (so no held-out building); a set too large for the split, or ``K`` below ``N``, is refused
    naming the option and its limit; the record's digest of both is what the leakage check rebuilds."""
    from ogm_ppl.datasets import floorplans as fp

    split = fp.training_plans("schools")
    vals = []
    for n in (3, 10, 20):
        tr, val, rec = leakage.guide_split("schools", n, 1, 8, after=20)
        assert tr == leakage.guide_plans("schools", n, 1)[0] and len(val) == 8 and val == sorted(val)
        assert not set(tr) & set(val) and set(tr) | set(val) <= set(split)
        assert rec["sample"]["validation"] == {"plans": 8, "after": 20, "rule": leakage.VALIDATION_RULE}
        vals.append(val)
    assert vals[0] == vals[1] == vals[2]
    assert not set(vals[0]) & set(leakage.guide_plans("schools", 20, 1)[0])
    _, own, _ = leakage.guide_split("schools", 3, 1, 8)  # after defaults to the sample: the next 8
    assert not set(own) & set(leakage.guide_plans("schools", 3, 1)[0])
    with pytest.raises(ValueError, match=rf"--validation-sample may be at most {len(split) - 30}"):
        leakage.guide_split("schools", 3, 1, len(split), after=30)
    with pytest.raises(ValueError, match="--validation-after must be a whole number of at least --sample"):
        leakage.guide_split("schools", 10, 1, 8, after=5)
    with pytest.raises(ValueError, match="--validation-sample must be a whole number of at least 1"):
        leakage.guide_split("schools", 10, 1, 0)
    tr, val, rec = leakage.guide_split("schools", 3, 1, 8, after=20)
    meta = {"corpus": "schools", **rec, "plan_names_sha256": leakage.names_digest(tr + val)}
    assert leakage.guide_training_sets("schools", meta) == {"schools": set(tr) | set(val)}
    meta["sample"]["validation"]["after"] = 21  # another validation set than the plans it names
    with pytest.raises(LeakageError, match="not the random sample of its training split"):
        leakage.guide_training_sets("schools", meta)
    del meta["sample"]["validation"]["after"]
    with pytest.raises(LeakageError, match="malformed sample"):
        leakage.guide_training_sets("schools", meta)
