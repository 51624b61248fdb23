"""ogm_ppl.studies.amortised_guide_eval on tiny settings: held-out maps are reproducible from the seed, every
sampler's curves have one value per sweep, the scores and rates are in range, and the summary averages the
per-map results."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from ogm_ppl.datasets.mapgen import KINDS
from ogm_ppl.studies.amortised_guide_eval import (
    THRESHOLDS,
    GuideEvalSettings,
    GuideEvalSettingsError,
    guide_eval,
    make_maps,
    markdown,
    sweeps_to,
)

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "amortised_guide_eval.py"
TINY = GuideEvalSettings(
    maps_a=1, maps_b=1, size=16, ref_warmup=10, ref_sweeps=40, chains=2, sweeps=12, acc_passes=1, block=(3, 3)
)
SAMPLERS = ["gibbs_default_init", "gibbs_guide_init", "gibbs_guide_tile_init", "guided_tiles", "guided_bernoulli"]


@pytest.fixture(scope="module")
def result():
    # the script's numeric context, whatever earlier tests of this process left: one thread, float32 default,
    # an empty parameter store
    import pyro

    torch.set_num_threads(1)
    torch.set_default_dtype(torch.float32)
    pyro.clear_param_store()
    return guide_eval(TINY, progress=False)


def test_sweeps_to():
    assert sweeps_to(np.array([0.01, 0.02]), 0.05) == 1  # within from the first sweep
    assert sweeps_to(np.array([0.5, 0.1, 0.3, 0.01, 0.02]), 0.05) == 4
    assert sweeps_to(np.array([0.01, 0.5, 0.01]), 0.05) == 3  # leaving the band resets the count
    assert sweeps_to(np.array([0.5, 0.01, 0.5]), 0.05) is None  # not within at the horizon


def test_the_held_out_maps_follow_the_seed():
    a, b = make_maps(TINY), make_maps(TINY)
    assert [m["set"] for m in a] == ["A:prior", "B:mapgen"] and [m["name"] for m in a] == ["prior_0", f"{KINDS[0]}_0"]
    for x, y in zip(a, b):
        assert x["truth"].shape == (16, 16)
        np.testing.assert_array_equal(x["truth"], y["truth"])
    other = make_maps(GuideEvalSettings(**{**TINY.__dict__, "seed": 7}))
    assert any(not np.array_equal(x["truth"], y["truth"]) for x, y in zip(a, other))
    window = a[1]["truth"]
    assert 0.1 < window.mean() < 0.6  # set B's windows hold some wall and some free space


def test_every_map_is_scored_and_every_sampler_has_its_curves(result):
    assert [r["set"] for r in result.per_map] == ["A:prior", "B:mapgen"]
    for r in result.per_map:
        assert r["cells"] > 0 and 0 <= r["occupied_share"] <= 1
        for meth in ("guide", "gibbs_long", "p21_ogm"):
            s = r["methods"][meth]
            assert 0 <= s["best_f1"] <= 1 and 0 <= s["auc"] <= 1 and s["nll_bits"] > 0 and 0 <= s["ece"] <= 1
            assert s["seconds"] > 0
        assert r["methods"]["gibbs_long"]["sweeps"] == 2 * (10 + 40)
        assert 0 <= r["guide_vs_ref_mean_abs"] <= 1 and 0 <= r["ensemble_noise_floor"] <= 0.5
        assert list(r["convergence"]) == SAMPLERS
        for name, c in r["convergence"].items():
            assert len(c["running_dist"]) == len(c["ensemble_excess"]) == len(c["log_joint_gap"]) == 12
            assert all(0 <= d <= 1 for d in c["running_dist"])
            assert c["sweeps_to"] == {str(d): sweeps_to(np.array(c["running_dist"]), d) for d in THRESHOLDS}
            assert ("guide_acceptance" in c) == name.startswith("guided")
            assert 0 <= c.get("guide_acceptance", 0) <= 1
        assert set(r["acceptance_by_block"]) == {
            "bernoulli_1x1",
            "bernoulli_3x3",
            "bernoulli_6x6",
            "tiles_3x3",
            "tiles_6x6",
            "tiles_9x9",
        }
        assert all(0 <= a <= 1 for a in r["acceptance_by_block"].values())


def test_the_summary_averages_the_maps(result):
    s = result.summary
    assert list(s) == ["A:prior", "B:mapgen", "all"] and [v["maps"] for v in s.values()] == [1, 1, 2]
    for meth in ("guide", "gibbs_long", "p21_ogm"):
        per_map = [r["methods"][meth]["nll_bits"] for r in result.per_map]
        assert s["all"]["scores"][meth]["nll_bits"] == pytest.approx(np.mean(per_map), rel=1e-12)
        assert s["A:prior"]["scores"][meth]["nll_bits"] == per_map[0]
    assert s["all"]["convergence"]["guided_tiles"]["reached_0.05"].endswith("/2")
    assert result.trained_for and result.seconds > 0
    md = markdown(s, TINY, result.trained_for)
    assert "## Set all (2 maps)" in md and "| guided_bernoulli |" in md and "dist@12" in md
    json.dumps(result.per_map)  # the per-map results are plain JSON


def test_bad_settings_are_refused():
    for kwargs, match in (
        ({"sweeps": 0}, "sweeps: must be at least 1"),
        ({"maps_a": 0, "maps_b": 0}, "maps_a: maps_a \\+ maps_b must be at least 1"),
        ({"size": 100}, "size: must be between 3 and 95"),
        ({"p_guide": 1.5}, "p_guide: must be between 0 and 1"),
        ({"block": (0, 3)}, "block: must be two sides"),
    ):
        with pytest.raises(GuideEvalSettingsError, match=match):
            GuideEvalSettings(**kwargs)


def test_the_script_writes_the_library_numbers(result, tmp_path):
    tiny = ["--maps-a", "1", "--maps-b", "1", "--size", "16", "--ref-warmup", "10", "--ref-sweeps", "40"]
    tiny += ["--chains", "2", "--sweeps", "12", "--acc-passes", "1", "--block", "3", "3"]
    r = subprocess.run(
        [sys.executable, str(SCRIPT), *tiny, "--out", str(tmp_path)], capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["settings"] == {**TINY.__dict__, "block": [3, 3], "out": str(tmp_path)}
    for got, want in zip(doc["per_map"], result.per_map, strict=True):
        assert got["methods"]["guide"]["nll_bits"] == want["methods"]["guide"]["nll_bits"]
        assert got["ref_chain_gap"] == want["ref_chain_gap"]
        for name in SAMPLERS:
            assert got["convergence"][name]["running_dist"] == want["convergence"][name]["running_dist"]
    assert (tmp_path / "results.md").read_text() in r.stdout
    r = subprocess.run(
        [sys.executable, str(SCRIPT), "--sweeps", "0", "--out", str(tmp_path / "x")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 2 and "--sweeps: must be at least 1" in r.stderr, r.stderr
    assert not (tmp_path / "x").exists()
