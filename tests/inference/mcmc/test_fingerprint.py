"""prior_name_digest: one digest of a prior by name, for every result that must be recomputed when the prior
changes under its name (experiment runs, calibration rows, the command line's checkpoints)."""

import pytest

from ogm_ppl.inference.mcmc.fingerprint import prior_digest, prior_name_digest
from ogm_ppl.priors import IndependentPrior, prior_by_name, register_prior, unregister_prior


def test_the_digest_of_a_name_is_its_priors_on_8_x_8_and_changes_with_the_prior():
    assert prior_name_digest("mrf:houseexpo") == prior_digest(prior_by_name("mrf:houseexpo", (8, 8)), 64)
    assert prior_name_digest("mrf:houseexpo") != prior_name_digest("mrf:ipa")
    register_prior("fp_probe", lambda shape, tables: IndependentPrior(0.3, shape[0] * (shape[1] if shape[1:] else 1)))
    try:
        before = prior_name_digest("fp_probe")
        unregister_prior("fp_probe")
        register_prior("fp_probe", lambda shape, tables: IndependentPrior(0.4, 8 if len(shape) == 1 else 64))
        assert prior_name_digest("fp_probe") != before
    finally:
        unregister_prior("fp_probe")


def test_a_1d_only_kind_is_digested_on_8_cells_and_a_bad_name_says_why():
    register_prior("fp_line", lambda shape, tables: IndependentPrior(0.3, 8) if len(shape) == 1 else 1 / 0)
    try:
        assert prior_name_digest("fp_line") == prior_digest(IndependentPrior(0.3, 8), 8)
    finally:
        unregister_prior("fp_line")
    with pytest.raises(ValueError, match=r"^unknown prior kind 'no_such_kind'"):
        prior_name_digest("no_such_kind")


def test_a_net_fields_memo_filled_by_sweeps_leaves_its_digest_as_it_was():
    # the memo is a cache of the sweeps: a digest that followed it made every checkpoint of a net prior's chain
    # "belong to another run" when the command line resumed it at its next mark
    prior = prior_by_name("net:houseexpo", (8, 8))
    before = prior_digest(prior, 64)
    bundle = prior.compiled()
    for name in bundle.cache_fields():
        getattr(bundle, name)[:] = 7
    assert prior_digest(prior, 64) == before
    assert prior_digest(prior_by_name("net:houseexpo@0.5", (8, 8)), 64) != before
