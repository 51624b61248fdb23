"""ogm_ppl.calibration.chains: the patch rule follows the compiled bundle, a prior over the support limit or
without a fitted exponent is skipped, and the tempering kernel scores the cold rung of its ladder."""

import math

import pytest

from ogm_ppl.calibration import KERNELS, RHAT_THRESHOLD, STARTS, chains, default_patch, run_prior, support
from ogm_ppl.priors.named import prior_by_name
from tests.calibration._tiny import box_scene, tiny


def test_default_patch_follows_the_compiled_bundle():
    shape = (12, 12)
    got = {k: default_patch(prior_by_name(f"{k}:houseexpo", shape)) for k in ("mrf", "patch3", "border", "border1")}
    assert got == {"mrf": None, "patch3": (3, 3), "border": (3, 3), "border1": None}
    assert math.isclose(RHAT_THRESHOLD, 1.05)


def test_a_prior_over_the_support_limit_is_skipped():
    settings = tiny(max_support=100)
    scene = box_scene(settings)
    assert support(prior_by_name("patch3:houseexpo", (24, 24)), (3, 3)) == 512
    assert support(prior_by_name("mrf:houseexpo", (24, 24)), None) == 2
    assert "512 configurations" in run_prior(scene, "patch3:houseexpo", settings)["skipped"]
    res = run_prior(scene, "mrf:houseexpo", settings)
    assert res["patch"] is None and len(res["seconds_per_chain"]) == 3
    assert res["scores"]["unseen"]["cells"] == res["rhat_cells"] == int(scene.masks["unseen"].sum())


def test_tempering_kernel_scores_the_cold_rung_of_its_ladder(monkeypatch):
    from ogm_ppl.inference.mcmc.tempering import ParallelTempering

    settings = tiny(kernel="tempering", rungs=3, beta_min=0.25, temper="both")
    built = []

    def spy(model, patch, init, options):
        kernel = chains.tempering_kernel(model, patch, init, options)
        built.append((patch, kernel))
        return kernel

    monkeypatch.setitem(KERNELS, "tempering", spy)
    scene = box_scene(settings)
    for name, patch in (("mrf:houseexpo", None), ("patch3:houseexpo", (3, 3))):
        built.clear()
        res = run_prior(scene, name, settings)
        assert len(built) == len(STARTS) == len(res["seconds_per_chain"])
        for p, kernel in built:
            assert p == patch and isinstance(kernel, ParallelTempering)
            assert list(kernel.betas) == pytest.approx([1.0, 0.5, 0.25]) and kernel.temper == "both"
        unseen = res["scores"]["unseen"]
        assert unseen["cells"] == res["rhat_cells"] == int(scene.masks["unseen"].sum()) and unseen["nll_bits"] > 0


def test_guided_kernel_wraps_the_gibbs_sampler_with_the_proposal_guide_from_each_start(monkeypatch):
    """``kernel = "guided"``: each chain is :class:`GuidedGibbs` around the sampler ``gibbs`` would use, proposing
    from the named guide (symmetrised for ``@sym``) and started at the chain's own start, not the guide's mode."""
    from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
    from ogm_ppl.inference.mcmc.guided import GuidedGibbs

    settings = tiny(kernel="guided", proposal_guide="ipa@sym")
    built = []

    def spy(model, patch, init, options):
        kernel = chains.guided_kernel(model, patch, init, options)
        built.append((init, kernel))
        return kernel

    monkeypatch.setitem(KERNELS, "guided", spy)
    scene = box_scene(settings)
    for name, base in (("mrf:houseexpo", CellGibbs), ("patch3:houseexpo", PatchGibbs)):
        built.clear()
        res = run_prior(scene, name, settings)
        assert [i for i, _ in built] == list(STARTS)
        for init, kernel in built:
            assert isinstance(kernel, GuidedGibbs) and isinstance(kernel.base, base) and kernel.init == "base"
            assert kernel.base.init == init and kernel.guide.symmetrize and kernel.guide_sweeps > 0
        assert res["scores"]["unseen"]["cells"] == res["rhat_cells"] > 0


def test_a_tempered_kind_without_a_fitted_exponent_is_skipped():
    from ogm_ppl.priors.named import load_temper_params

    assert "patch5" not in load_temper_params("ipa").beta
    settings = tiny()
    res = run_prior(box_scene(settings), "patch5:ipa@cal", settings)
    assert "no tempering exponent fitted for patch5 on ipa" in res["skipped"]


def test_a_biased_name_without_its_bias_is_refused():
    settings = tiny()
    with pytest.raises(ValueError, match="no bias given for mrf:houseexpo"):
        run_prior(box_scene(settings), "mrf:houseexpo+bias", settings, bias={})
