"""The amortised guide q(m | z): features, Pyro habits, the CSIS objective, safe artefacts, the shipped guide."""

import copy
import hashlib
import json
import math

import numpy as np
import pyro
import pytest
import torch
from pyro.infer import CSIS, Predictive
from pyro.optim import Adam

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.inference.log_odds import evidence_grid
from ogm_ppl.inference.variational.amortised import (
    SHIPPED_GUIDE,
    AmortisedGuide,
    GuideFileError,
    evidence_features,
    feature_names,
    guide_initial_map,
    random_scene,
    shipped_guide,
)
from ogm_ppl.metrics import nll_bits
from ogm_ppl.models.delta import delta_by_name
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.priors.named import prior_by_name


def small_model(seed=0, shape=(12, 10), poses=2, prior=None, max_range=6.0, sensor=None):
    prior = prior if prior is not None else prior_by_name("patch3:generated", shape)
    scene = random_scene(
        prior, shape, poses, beams=36, max_range_cells=max_range, sensor=sensor, rng=np.random.default_rng(seed)
    )
    m0 = scene.model()
    gen = torch.Generator().manual_seed(seed)
    truth = m0.prior.sample_given_free(m0.known_free, (), generator=gen)
    z = m0.simulate_readings(truth, generator=gen)
    return scene, scene.model(z), truth, z


def test_features_match_the_evidence_grid_and_the_rays():
    scene, model, _, z = small_model()
    x = evidence_features(model)
    assert x.dtype == torch.float32 and x.shape == (len(feature_names()), 12, 10)
    names = feature_names()
    lo = x[names.index("log_odds")].double().flatten() * 4
    want = evidence_grid(model.rays, delta_by_name("p21")).log_odds.clamp(-12, 12)
    torch.testing.assert_close(lo, want, rtol=0, atol=1e-5)
    r = model.rays
    hits = torch.expm1(x[names.index("hit_count")].double()).flatten().round()
    in_grid = (~r.is_max) & (r.z < r.lengths)
    assert int(hits.sum()) == int(in_grid.sum())
    observed = x[names.index("observed")].flatten().bool()
    assert torch.equal(observed, torch.from_numpy(r.reached()).bool())
    assert torch.equal(x[names.index("pinned")].flatten().bool(), model.known_free)
    # the placeholder model's features of the same readings are the same (negative ranges read as 0)
    torch.testing.assert_close(evidence_features(scene.model(), z), x, rtol=0, atol=0)
    # a batch of readings gives the features of each
    z2 = torch.stack([z, scene.model().simulate_readings(torch.zeros(model.num_cells))])
    xb = evidence_features(model, z2)
    assert xb.shape == (2, *x.shape)
    torch.testing.assert_close(xb[0], x)
    with pytest.raises(ValueError, match="one range per ray"):
        evidence_features(model, z[:-1])


def test_guide_samples_site_m_like_the_model():
    _, model, truth, _ = small_model(1)
    guide = AmortisedGuide(model, seed=1)
    tr = pyro.poutine.trace(guide).get_trace()
    m = tr.nodes["m"]["value"]
    assert m.shape == (len(model.latent),) and m.dtype == torch.float64 and ((m == 0) | (m == 1)).all()
    mtr = pyro.poutine.trace(pyro.poutine.replay(model.model, tr)).get_trace()
    assert torch.equal(mtr.nodes["m"]["value"], m) and mtr.nodes["map"]["value"].shape == (model.num_cells,)
    p = guide.marginals()
    assert p.shape == (model.num_cells,) and (p[model.known_free] == 0).all() and ((p >= 0) & (p <= 1)).all()
    lp = guide.log_prob(truth)
    want = torch.distributions.Bernoulli(probs=p[model.latent]).log_prob(truth[model.latent]).sum()
    torch.testing.assert_close(lp, want, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(guide.log_prob(truth[model.latent]), lp)
    maps = guide.sample_maps(n=500, generator=torch.Generator().manual_seed(0))
    assert maps.shape == (500, model.num_cells) and (maps[:, model.known_free] == 0).all()
    assert (maps.mean(0) - p).abs().max() < 5 * 0.5 / math.sqrt(500)
    init = guide_initial_map(guide, model)
    assert torch.equal(init, (p > 0.5).double())
    assert guide_initial_map(guide, model, "sample").shape == (model.num_cells,)
    with pytest.raises(ValueError, match="how"):
        guide_initial_map(guide, model, "mean")


def test_predictive_and_a_csis_step():
    _, model, _, _ = small_model(2, shape=(6, 6), poses=1)
    guide = AmortisedGuide(model, seed=2)
    pred = Predictive(model.model, guide=guide, num_samples=3)()
    assert pred["m"].shape == (3, len(model.latent)) and pred["map"].shape == (3, model.num_cells)
    with pytest.raises(ValueError, match="readings=None"):
        guide(readings=None)
    # guide(observations=...) is what pyro.infer.CSIS calls: it trains the same objective
    pyro.clear_param_store()
    before = {k: v.detach().clone() for k, v in guide.net.state_dict().items()}
    csis = CSIS(model.model, guide, Adam({"lr": 1e-2}), training_batch_size=2)
    loss = csis.step()
    assert math.isfinite(loss)
    names = set(pyro.get_param_store().keys())
    assert f"{guide.name}.net.convs.0.weight" in names
    assert any(not torch.equal(before[k], v) for k, v in guide.net.state_dict().items())
    other = AmortisedGuide(model)
    assert other.name != guide.name  # parameters of two guides never share a name


def test_training_the_csis_loss_lowers_it_on_fresh_draws():
    scene, _, _, _ = small_model(3, shape=(9, 9), poses=2, prior=IndependentPrior(0.3, 81))
    m0 = scene.model()
    gen = torch.Generator().manual_seed(0)
    guide = AmortisedGuide(channels=8, dilations=(1, 1), phase=(0, 0), seed=0)

    def batch(n):
        maps = m0.prior.sample_given_free(m0.known_free, (n,), generator=gen)
        return maps, m0.simulate_readings(maps, generator=gen)

    test = batch(64)
    with torch.no_grad():
        start = float(guide.csis_loss(m0, *test))
    opt = torch.optim.Adam(guide.parameters(), lr=3e-2)
    for _ in range(25):
        loss = guide.csis_loss(m0, *batch(8))
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        end = float(guide.csis_loss(m0, *test))
    assert end < start - 5.0, (start, end)


def test_save_load_round_trip_and_refusals(tmp_path):
    _, model, _, _ = small_model(4)
    g = AmortisedGuide(model, channels=6, dilations=(1, 2), seed=4)
    path = g.save(tmp_path / "g.npz", meta={"prior": "patch3:generated"})
    h = AmortisedGuide.load(path, model)
    torch.testing.assert_close(h.cell_logits(), g.cell_logits(), rtol=0, atol=0)
    assert h.trained_for == {"prior": "patch3:generated"} and h.name != g.name
    k = AmortisedGuide(model, channels=6, dilations=(1, 2), seed=9)
    k.load_weights(path)
    torch.testing.assert_close(k.cell_logits(), g.cell_logits(), rtol=0, atol=0)
    # another architecture: refused, naming the path and the field
    with pytest.raises(GuideFileError, match=r"g\.npz.*channels: file 6, guide 16"):
        AmortisedGuide(model).load_weights(path)
    with pytest.raises(GuideFileError, match="dilations"):
        AmortisedGuide(model, channels=6, dilations=(1, 1)).load_weights(path)

    good = dict(np.load(path, allow_pickle=False))

    def tampered(name, **changes):
        d = {**good, **changes}
        for k, v in list(d.items()):
            if v is None:
                del d[k]
        p = tmp_path / f"{name}.npz"
        np.savez(p, **d)
        return p

    w = "param/convs.0.weight"
    cases = {
        "shape": ({w: good[w][:, :, :2]}, "has shape"),
        "nan": ({w: np.full_like(good[w], np.nan)}, "non-finite"),
        "dtype": ({w: good[w].astype(np.float64)}, "float32"),
        "missing": ({w: None}, "missing"),
        "extra": ({"param/evil": np.zeros(3, np.float32)}, "unexpected"),
        "kind": ({"kind": np.array("something else")}, "kind"),
        "format": ({"format": np.array(99)}, "format 99"),
        "features": ({"feature_version": np.array(7)}, "feature set"),
        "channels": ({"channels": np.array(7)}, "has shape"),
        "dilation0": ({"dilations": np.array([0, 1])}, "dilations"),
        "phase": ({"phase": np.array([3, 0])}, "phase"),
        "delta": ({"delta": np.array("no_such_delta")}, "delta"),
        "meta": ({"meta": np.array("{not json")}, "meta"),
        "chtype": ({"channels": np.array(6.0)}, "integer"),
    }
    for name, (changes, msg) in cases.items():
        p = tampered(name, **changes)
        with pytest.raises(GuideFileError, match=msg) as e:
            AmortisedGuide.load(p)
        assert str(p) in str(e.value), name
    pickled = tmp_path / "p.npz"
    np.savez(pickled, **{**good, "meta": np.array([{"a": 1}], dtype=object)})
    with pytest.raises(GuideFileError, match=r"p\.npz: holds pickled Python objects; refused"):
        AmortisedGuide.load(pickled)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")  # a text file: not numpy's misleading "contains pickled (object) data"
    with pytest.raises(GuideFileError, match=r"junk\.npz: not an \.npz archive \(it does not start as a zip"):
        AmortisedGuide.load(junk)
    broken = tmp_path / "broken.npz"
    broken.write_bytes(b"PK\x03\x04 cut short")
    with pytest.raises(GuideFileError, match=r"broken\.npz: not a readable \.npz"):
        AmortisedGuide.load(broken)
    with pytest.raises(GuideFileError, match="no such file"):
        AmortisedGuide.load(tmp_path / "absent.npz")
    with pytest.raises(ValueError, match="architecture"):
        AmortisedGuide(channels=0)


def test_works_on_a_1d_grid_and_any_2d_size():
    grid = Grid.line(8)
    model = OccupancyModel(
        grid, raycast(grid, Scans.one_d([3.0, 5.0], max_range=6.0)), GaussianRange(1.0), IndependentPrior(0.3, 8)
    )
    g = AmortisedGuide(model, phase=(0, 0))
    assert g.marginals().shape == (8,)
    for shape in [(5, 7), (13, 4)]:
        _, m, _, _ = small_model(5, shape=shape, poses=1)
        assert AmortisedGuide(m).marginals().shape == (shape[0] * shape[1],)


def test_the_shipped_guide_loads_and_beats_a_uniform_guess_on_held_out_maps():
    """Small (<200 KB), safe-loaded, its sidecar's hash matches, and on maps it never saw (a seed stream
    the training did not use) its NLL is below 1 bit per cell (the uniform 0.5 guess) and below the
    prior's occupied share as a constant guess."""
    assert SHIPPED_GUIDE.stat().st_size < 200_000
    record = json.loads(SHIPPED_GUIDE.with_suffix(".json").read_text())
    assert record["sha256"] == hashlib.sha256(SHIPPED_GUIDE.read_bytes()).hexdigest()
    assert record["heldout"]["bits_per_cell"] < record["heldout"]["bits_per_cell_prior_share_guess"]
    guide = shipped_guide()
    meta = guide.trained_for
    assert meta["prior"] == "patch3:generated"
    shape = (24, 24)
    prior = prior_by_name(meta["prior"], shape)
    rng = np.random.default_rng(987654321)
    ours, share = [], []
    for _ in range(4):
        scene = random_scene(prior, shape, 3, meta["beams"], meta["max_range_cells"], GaussianRange(1.0), rng)
        m0 = scene.model()
        gen = torch.Generator().manual_seed(int(rng.integers(2**31)))
        truth = m0.prior.sample_given_free(m0.known_free, (), generator=gen)
        model = scene.model(m0.simulate_readings(truth, generator=gen))
        mask = ~model.known_free.numpy()
        q = guide.marginals(model)
        ours.append(nll_bits(q, truth.numpy(), mask=mask))
        share.append(nll_bits(np.full(model.num_cells, prior.mean_occupancy), truth.numpy(), mask=mask))
    assert np.mean(ours) < 1.0 and np.mean(ours) < np.mean(share), (ours, share)


@pytest.mark.parametrize("corpus", ["houseexpo", "ipa", "dungeon", "houseexpo+ipa"])
def test_a_corpus_guide_ships_safely_and_predicts_unseen_cells_of_a_held_out_plan(corpus):
    """Each shipped corpus guide: small, its sidecar's hash matches, its record names the corpus (or corpora,
    ``C1+C2``) and the SHA-256 of each corpus's tables' training plans; on the first held-out plan of each
    corpus (never trained on), scanned as the calibration experiment scans, its NLL on the cells no ray reached
    but within 10 cells of one is below the uniform guess (1 bit) and below traditional OGM's there."""
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.datasets.stop_and_scan import stop_and_scan
    from ogm_ppl.inference.variational.amortised import corpus_guide, corpus_guide_path, corpus_guides
    from ogm_ppl.metrics import near_mapped_mask

    path = corpus_guide_path(corpus)
    assert corpus in corpus_guides() and path.stat().st_size < 300_000
    record = json.loads(path.with_suffix(".json").read_text())
    assert record["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    guide = corpus_guide(corpus)
    meta = guide.trained_for
    assert meta["corpus"] == corpus
    parts = corpus.split("+")
    for part in parts:
        own = meta if len(parts) == 1 else meta["corpora"][part]
        prov = json.loads((path.parent / f"prior_{part}.json").read_text())["provenance"]
        train = fp.training_plans(part, exclude_buildings=tuple(prov["excluded_buildings"]), limit=int(prov["plans"]))
        assert own["plan_names_sha256"] == hashlib.sha256("\n".join(sorted(train)).encode()).hexdigest()
        name = fp.heldout_plans(part, exclude_buildings=tuple(fp.REAL_LOG_BUILDINGS))[0]
        assert name not in train
        plan = fp.load_plan(part, name)
        truth, known = plan.occupancy[:96, :96], plan.known[:96, :96]
        grid = Grid(truth.shape, resolution=plan.resolution or 0.05)
        sc = meta["scans"]
        data = stop_and_scan(
            truth, grid, num_poses=sc["poses"], beams=sc["beams"], max_range_cells=sc["range_cells"], sigma_cells=1.0
        )
        rays = raycast(grid, data.scans)
        model = OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, grid.num_cells))
        reached = rays.reached().reshape(grid.shape)
        unseen = (near_mapped_mask(reached, 10.0) & known & ~reached).ravel()
        assert unseen.sum() > 50
        ours = nll_bits(guide.marginals(model), truth.ravel(), mask=unseen)
        ogm = evidence_grid(rays, delta_by_name("p21"), check_setting=False).probabilities
        assert ours < 1.0 and ours < nll_bits(ogm, truth.ravel(), mask=unseen), (part, ours)


def test_an_unknown_corpus_guide_is_refused_with_the_list():
    from ogm_ppl.inference.variational.amortised import corpus_guide
    from ogm_ppl.methods.params import GuideFile, _Bad

    with pytest.raises(GuideFileError, match=r"no guide learned on corpus 'nowhere'; shipped: .*houseexpo"):
        corpus_guide("nowhere")
    assert GuideFile().value("corpus:ipa") == "corpus:ipa"
    with pytest.raises(_Bad, match="no guide learned on corpus 'nowhere'"):
        GuideFile().value("corpus:nowhere")


def test_one_message_names_the_shipped_corpora_and_the_case_sensitive_name():
    """corpus_guide, the start map option and the guide option refuse an unknown corpus with one message: the
    name (no file path), the shipped corpora, a hint for a name in other case, and how to train one."""
    from ogm_ppl.inference.variational.amortised import corpus_guide, corpus_guides, unknown_corpus_message
    from ogm_ppl.methods.params import GuideFile, StartMap, _Bad

    assert {"dungeon", "generated", "houseexpo", "ipa"} <= set(corpus_guides())
    msg = unknown_corpus_message("nope")
    assert msg == (
        f"no guide learned on corpus 'nope'; shipped: {', '.join(corpus_guides())} "
        "(ogm-ppl train-guide --corpus C --out FILE.npz trains one: ogm_ppl.learn.train_corpus_guide)"
    )
    with pytest.raises(GuideFileError) as e:
        corpus_guide("nope")
    assert str(e.value) == msg and isinstance(e.value, ValueError)
    with pytest.raises(_Bad) as b:
        StartMap("ogm").value("guide:nope")
    assert str(b.value) == msg
    with pytest.raises(_Bad) as b:
        GuideFile().value("corpus:nope")
    assert str(b.value) == msg
    with pytest.raises(GuideFileError, match=r"^no guide learned on corpus 'HouseExpo' \(did you mean 'houseexpo'\?\)"):
        corpus_guide("HouseExpo")
    assert "did you mean" not in unknown_corpus_message("nope") + unknown_corpus_message("dungeon2")
    with pytest.raises(GuideFileError, match="'amortised'"):  # the shipped guide of Section 2.6 is no corpus's
        corpus_guide("amortised")


def test_a_guide_of_plan_files_names_them_in_its_setting_warning(tmp_path):
    """A guide trained on plan files of one's own (record ``corpus = "files"``) tells to train with
    ``--plan-files``, not a corpus of that name."""
    from ogm_ppl.inference.variational import FittedSettingWarning

    AmortisedGuide(channels=2, dilations=(1,), phase=(0, 0), seed=0).save(
        tmp_path / "g.npz", {"corpus": "files", "scans": {"range_cells": 75.0, "sigma_cells": 1.0}}
    )
    prior = IndependentPrior(0.5, 16 * 14)
    _, short, _, _ = small_model(1, shape=(16, 14), prior=prior, max_range=6.0)
    want = r"on plan files was trained .* train-guide --plan-files PLANS --range-cells 6 --sigma 1 --out FILE\.npz"
    with pytest.warns(FittedSettingWarning, match=want):
        assert not AmortisedGuide.load(tmp_path / "g.npz").check_setting(short)


def test_a_corpus_guide_warns_once_outside_the_sensor_it_was_trained_for():
    """A corpus guide records its sensor (F = 75 cells, sigma = 1 cell for houseexpo): a model far from it
    (range beyond a factor 2, sigma beyond 25 %) warns once, naming both values and how to train one; inside,
    or with a guide that records no sensor, it is silent."""
    import warnings

    from ogm_ppl.inference.variational import FittedSettingWarning
    from ogm_ppl.inference.variational.amortised import corpus_guide

    guide = corpus_guide("houseexpo")
    prior = IndependentPrior(0.5, 16 * 14)
    _, near, _, _ = small_model(1, shape=(16, 14), prior=prior, max_range=50.0, sensor=GaussianRange(1.2))
    with warnings.catch_warnings():
        warnings.simplefilter("error", FittedSettingWarning)
        guide.marginals(near)
        assert guide.check_setting(near)
        shipped_guide().marginals(near)  # records no corpus sensor
    _, short, _, _ = small_model(1, shape=(16, 14), prior=prior, max_range=6.0)
    with pytest.warns(FittedSettingWarning) as rec:
        guide.marginals(short)
        guide.marginals(short)
        guide_initial_map(guide, short)
    assert len(rec) == 1
    text = str(rec[0].message)
    assert "'houseexpo' was trained for F = 75 cells, sigma = 1 cells but is used at F = 6 cells" in text
    assert "factor 2" in text
    assert "ogm-ppl train-guide --corpus houseexpo --range-cells 6 --sigma 1 --out FILE.npz" in text
    assert "ogm_ppl.learn.train_corpus_guide" in text
    with pytest.warns(FittedSettingWarning, match=r"train-guide --corpus houseexpo ipa --range-cells 6 --sigma 1"):
        corpus_guide("houseexpo+ipa").check_setting(short)  # the command line names each corpus
    _, noisy, _, _ = small_model(1, shape=(16, 14), prior=prior, max_range=75.0, sensor=GaussianRange(3.0))
    with pytest.warns(FittedSettingWarning, match=r"sigma 3 cells is not within 25% of 1.*--sigma 3"):
        assert not guide.check_setting(noisy)
    with warnings.catch_warnings():
        warnings.simplefilter("error", FittedSettingWarning)
        assert guide.check_setting(noisy, noise_known=False)  # the range alone


def test_a_chain_starts_from_a_corpus_guides_mode():
    from ogm_ppl.inference.mcmc.kernel import initial_map
    from ogm_ppl.inference.variational.amortised import corpus_guide
    from ogm_ppl.methods.params import StartMap, _Bad

    # the houseexpo guide's sensor: F = 75 cells, sigma = 1 cell
    _, model, _, _ = small_model(3, shape=(16, 14), poses=2, prior=IndependentPrior(0.5, 16 * 14), max_range=75.0)
    m = initial_map(model, "guide:houseexpo")
    want = (corpus_guide("houseexpo").marginals(model) > 0.5).to(torch.float64)
    assert torch.equal(m, want) and not m[model.known_free].any()
    kind = StartMap("ogm", "free")
    assert kind.value("guide:dungeon") == "guide:dungeon" and kind.value("free") == "free"
    for bad in ("guide:nowhere", "somewhere"):
        with pytest.raises(_Bad, match=r"no guide learned|must be one of"):
            kind.value(bad)
    with pytest.raises(ValueError, match="guide:CORPUS"):
        initial_map(model, "nonsense")


def test_the_generated_corpus_guide_records_the_tables_maps_and_the_table_6_4_sensor():
    """The guide of the generated corpus was trained on the very maps its tables counted (their seed-stream
    names' SHA-256), scanned whole along planned routes with the Table 6.4 simulator (720 beams, F = 75,
    sigma = 3 cells)."""
    from ogm_ppl.inference.variational.amortised import corpus_guide, corpus_guide_path

    path = corpus_guide_path("generated")
    record = json.loads(path.with_suffix(".json").read_text())
    assert record["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest() and path.stat().st_size < 300_000
    meta = corpus_guide("generated").trained_for
    prov = json.loads((path.parent / "prior_generated.json").read_text())["provenance"]
    names = [
        f"seedstream:{c.entropy}/{tuple(c.spawn_key)}" for c in np.random.SeedSequence(prov["seed"]).spawn(prov["n"])
    ]
    assert meta["plan_names_sha256"] == hashlib.sha256("\n".join(sorted(names)).encode()).hexdigest()
    sc = meta["scans"]
    assert sc["whole_map"] and (sc["beams"], sc["range_cells"], sc["sigma_cells"]) == (720, 75.0, 3.0)


def test_symmetrised_logits_turn_with_the_scene_and_refuse_a_tiled_guide():
    """``symmetrize``: the mean over the 8 turns and flips commutes with every one of them (a plain guide's
    logits do not), and equals ``cell_logits`` of the guide; a guide with tile-phase channels refuses it."""
    from ogm_ppl.inference.variational.amortised_net import _symmetrised

    _, model, _, _ = small_model(3, shape=(9, 13), poses=2)
    g = AmortisedGuide(model, phase=(0, 0), channels=6, dilations=(1, 2), seed=4)
    x = g.features(model)[None]
    sym = _symmetrised(g.net, x)
    # the commutation is checked in float64: in float32 each turn's convolutions sum in another order (and
    # oneDNN's blocking of those sums depends on the CPU and the thread count), so the turns' logits differ by
    # float32 roundings, which a fixed bound need not cover on every CPU. In float64 a convolution's sum of at
    # most 9 x 7 + 1 terms whose sizes add up to under 10 here rounds by under 64 * eps64 * 10 = 1.5e-13; the
    # three layers, the skip and the mean of 8 stay far below 1e-11.
    net64, x64 = copy.deepcopy(g.net).double(), x.double()
    sym64 = _symmetrised(net64, x64)
    with torch.no_grad():
        for k in range(4):
            for flip in (False, True):

                def t(a, k=k, flip=flip):
                    a = torch.rot90(a, k, dims=(-2, -1))
                    return torch.flip(a, dims=(-1,)) if flip else a

                torch.testing.assert_close(_symmetrised(net64, t(x64)), t(sym64), rtol=0, atol=1e-11)
        plain = g.net(x)
        assert (g.net(torch.rot90(x, 1, dims=(-2, -1))) - torch.rot90(plain, 1, dims=(-2, -1))).abs().max() > 1e-3
        g.symmetrize = True
        torch.testing.assert_close(g.cell_logits(model), sym.reshape(-1).double())
        assert not torch.allclose(g.cell_logits(model), plain.reshape(-1).double())
    with pytest.raises(ValueError, match="tile-phase channels"):
        AmortisedGuide(model).symmetrize = True
    with pytest.raises(TypeError, match="True or False"):
        g.symmetrize = "false"
