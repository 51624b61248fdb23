"""field_data_curve: the PL pattern field fitted on nested random samples of a corpus's training plans and scored
on the same validation plans (none of the test split), its file in the folder named only, the
fit-prior data-curve command, and refused options named."""

import json
import math

import numpy as np
import pytest

from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.learn import FitOptionError
from ogm_ppl.learn.data_curve import field_data_curve
from tests.datasets._corpus_fixtures import HOUSE


@pytest.fixture
def houses(tmp_path, monkeypatch):
    """Twelve two-room houses of ``houseexpo-full`` under ``$OGM_PPL_FLOORPLANS``."""
    from tests.datasets._corpus_fixtures import write_houseexpo

    lines = [
        json.dumps({"id": f"{k:04x}", "room_num": 2, "verts": [[x * (1 + k / 10), y] for x, y in HOUSE]})
        for k in range(12)
    ]
    write_houseexpo(tmp_path / "corpora", lines)
    monkeypatch.setenv("OGM_PPL_FLOORPLANS", str(tmp_path / "corpora"))


def test_curve_of_nested_samples_scored_on_the_same_validation_plans(houses, tmp_path):
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.learn._fit_common import sample_indices

    train = fp.training_plans("houseexpo-full")
    assert len(train) >= 5
    r = field_data_curve("houseexpo-full", tmp_path / "out", sizes=(2, 4), validation=1, seed=1, progress=False)
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["data_curve_houseexpo-full.json"]
    doc = json.loads(r.files[0].read_text())
    assert doc["provenance"]["command"] == (
        f"ogm-ppl fit-prior data-curve --corpus houseexpo-full --out {tmp_path / 'out'} --sizes 2 4 "
        "--validation 1 --seed 1"
    )
    rows = doc["rows"]
    assert [row["plans"] for row in rows] == [2, 4]
    # the samples are those of --sample with the same seed, and the validation plan is in neither
    for row in rows:
        names = [train[i] for i in sample_indices(len(train), row["plans"], 1)]
        assert row["names_sha256"] == fp_sha(names)
        assert math.isfinite(row["validation_pll_bits"]) and row["validation_pll_bits"] <= 0
        assert 0 <= row["validation_windows_unseen_share"] <= 1 and row["minutes_from_scratch"] >= 0
    perm = np.random.default_rng(1).permutation(len(train))
    assert doc["validation_names_sha256"] == fp_sha([train[int(perm[4])]])
    assert rows[1]["train_cells_pl"] > rows[0]["train_cells_pl"]


def fp_sha(names):
    import hashlib

    return hashlib.sha256("\n".join(names).encode()).hexdigest()


@pytest.mark.parametrize(
    ("kwargs", "option"),
    [
        ({"sizes": (4, 2)}, "sizes"),
        ({"sizes": (0,)}, "sizes"),
        ({"validation": 0}, "validation"),
        ({"sizes": (10**6,)}, "sizes"),
    ],
)
def test_bad_options_are_named(houses, tmp_path, kwargs, option):
    with pytest.raises(FitOptionError, match=option):
        field_data_curve("houseexpo-full", tmp_path / "out", progress=False, **{"validation": 1, **kwargs})
    assert not (tmp_path / "out").exists()


def test_the_command(houses, tmp_path, capsys):
    argv = ["fit-prior", "data-curve", "--corpus", "houseexpo-full", "--sizes", "3", "--validation", "1"]
    assert ogm_ppl([*argv, "--out", str(tmp_path / "c"), "--quiet"]) == 0
    assert "data_curve_houseexpo-full.json" in capsys.readouterr().out
    assert ogm_ppl([*argv, "--corpus", "generated", "--out", str(tmp_path / "d")]) == 2
