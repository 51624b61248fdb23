"""ogm_ppl.learn.train_prior_guide on tiny settings: trains the guide of a learned prior by inference
compilation, writes the guide and its record, gives the same weights for the same seed, and refuses bad options
naming them."""

import json

import pytest
import torch

from ogm_ppl.inference.variational.amortised import AmortisedGuide
from ogm_ppl.learn import GuideSettingsError, PriorGuideSettings, train_prior_guide

TINY = PriorGuideSettings(steps=3, batch=2, val_scenes=2, min_size=12, max_size=14, channels=4, dilations=(1, 2))


def test_a_prior_guide_trains_records_and_repeats(tmp_path):
    threads = torch.get_num_threads()
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    r = train_prior_guide(TINY, a, progress=False, command="python experiments/train_amortised_guide.py")
    assert torch.get_num_threads() == threads  # the settings' threads are torch's only while it trains
    side = json.loads(a.with_suffix(".json").read_text())
    assert r.path == a and r.sidecar == a.with_suffix(".json") and side == r.record
    assert side["trained_for"]["prior"] == "patch3:generated" and side["architecture"]["phase"] == [3, 3]
    assert side["training"]["maps_seen"] == 6 and side["heldout"]["scenes"] == 2
    assert side["provenance"]["command"] == "python experiments/train_amortised_guide.py"
    assert AmortisedGuide.load(a).trained_for == side["trained_for"]
    train_prior_guide(TINY, b, progress=False)  # same settings, same machine: the same weights
    sa, sb = AmortisedGuide.load(a).net.state_dict(), AmortisedGuide.load(b).net.state_dict()
    assert all(torch.equal(sa[k], sb[k]) for k in sa)


@pytest.mark.parametrize(
    ("kw", "option", "match"),
    [
        ({"steps": 0}, "steps", "--steps must be a whole number of at least 1"),
        ({"seed": -1}, "seed", "--seed must be a whole number of at least 0"),
        ({"sigma": float("nan")}, "sigma", "--sigma must be finite and above 0"),
        ({"min_size": 30, "max_size": 20}, "min_size", "--min-size 30 is above --max-size 20"),
        ({"dilations": ()}, "dilations", "--dilations must be whole numbers"),
    ],
)
def test_bad_prior_guide_options_are_refused_naming_them(kw, option, match):
    import dataclasses

    with pytest.raises(GuideSettingsError, match=match) as e:
        dataclasses.replace(TINY, **kw)
    assert e.value.option == option
