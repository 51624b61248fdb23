"""The corpus guide's data curve (``guide_data_curve``, ``ogm-ppl train-guide --curve-sizes``) on tiny settings:
one guide per size on nested samples, every one validated on the same plans and windows apart from all samples,
each recorded so the leakage checks rebuild its maps, a finished size reused, and bad options named before any
plan is read."""

import json

import pytest

from ogm_ppl.calibration import leakage
from ogm_ppl.cli import build_parser
from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.inference.variational.amortised import AmortisedGuide
from ogm_ppl.learn import FitOptionError, GuideSettingsError, GuideTrainingSettings
from ogm_ppl.learn import guide_training as gt
from ogm_ppl.learn.guide_curve import curve_settings, guide_data_curve

TINY = dict(examples=4, val=2, window=40, poses=2, beams=45, range_cells=30.0, channels=4, dilations=(1, 2, 1))
TEMPLATE = GuideTrainingSettings(corpus=("schools",), steps=2, eval_every=1, **TINY)


@pytest.fixture(scope="module")
def curve(tmp_path_factory):
    out = tmp_path_factory.mktemp("curve")
    r = guide_data_curve("schools", out, sizes=(2, 5), validation=3, seed=1, settings=TEMPLATE, progress=False)
    return out, r


def test_each_size_trains_on_its_sample_and_validates_on_one_shared_set(curve):
    out, r = curve
    doc = json.loads((out / "data_curve_guide_schools.json").read_text())
    assert r.files[0] == out / "data_curve_guide_schools.json"
    assert sorted(p.name for p in out.iterdir()) == [
        "data_curve_guide_schools.json",
        *(f"guide_schools_{n}.{e}" for n in (2, 5) for e in ("json", "npz")),
    ]
    assert doc["kind"] == "guide" and doc["settings"]["sizes"] == [2, 5] and doc["settings"]["validation"] == 3
    _, val, _ = leakage.guide_split("schools", 5, 1, 3)
    split = leakage.guide_base("schools")
    assert doc["validation_names_sha256"] == _sha("\n".join(n for n in split if n in set(val)))
    windows = set()
    for row, n in zip(doc["rows"], (2, 5), strict=True):
        meta = AmortisedGuide.load(out / f"guide_schools_{n}.npz").trained_for
        tr = leakage.guide_plans("schools", n, 1)[0]
        assert (meta["training_plans"], meta["validation_plans"]) == (n, 3) and row["plans"] == n
        assert meta["sample"]["validation"]["after"] == 5 and not set(tr) & set(val)
        assert leakage.guide_training_sets("schools", meta) == {"schools": set(tr) | set(val)}
        assert 1 <= row["training_plans_drawn"] <= n and row["validation_unseen_cells"] > 0
        assert 0 < row["validation_bits_per_unseen_cell_last"] < 10 and row["minutes_training"] >= 0
        windows.add(meta["validation"]["windows_sha256"])
    assert windows == {doc["validation_windows_sha256"]}  # the very same validation windows for both sizes
    assert doc["rows"][0]["validation_unseen_cells"] == doc["rows"][1]["validation_unseen_cells"]
    assert doc["provenance"]["command"] == (
        "ogm-ppl train-guide --corpus schools --examples 4 --val 2 --window 40 --poses 2 --beams 45 --range-cells "
        f"30.0 --channels 4 --dilations 1 2 1 --steps 2 --eval-every 1 --curve-sizes 2 5 --validation-sample 3 "
        f"--sample-seed 1 --out {out}"
    )


def _sha(text: str) -> str:
    import hashlib

    return hashlib.sha256(text.encode()).hexdigest()


def test_a_finished_size_is_reused_by_the_same_call(curve, monkeypatch):
    out, _ = curve
    before = json.loads((out / "data_curve_guide_schools.json").read_text())
    monkeypatch.setattr(gt, "train_corpus_guide", lambda *a, **k: pytest.fail("a finished guide was retrained"))
    again = guide_data_curve("schools", out, sizes=(2, 5), validation=3, seed=1, settings=TEMPLATE, progress=False)
    assert again.summary["rows"] == before["rows"]


def test_bad_options_are_named_before_any_plan_is_read(tmp_path):
    with pytest.raises(FitOptionError, match="curve_sizes: give ascending distinct sizes"):
        curve_settings(TEMPLATE, "schools", (5, 2), 3, 0)
    with pytest.raises(FitOptionError, match="validation_sample"):
        curve_settings(TEMPLATE, "schools", (2, 5), 0, 0)
    with pytest.raises(ValueError, match="--validation-sample may be at most"):
        guide_data_curve("schools", tmp_path / "c", sizes=(2, 30), validation=30, settings=TEMPLATE, progress=False)
    assert not (tmp_path / "c").exists()
    for kw, option in (
        ({"validation_sample": 3}, "validation_sample"),  # no --sample
        ({"sample": 5, "validation_after": 6}, "validation_after"),  # no --validation-sample
        ({"sample": 5, "validation_sample": 3, "validation_after": 4}, "validation_after"),  # below the sample
        ({"sample": 5, "validation_sample": 0}, "validation_sample"),
    ):
        with pytest.raises(GuideSettingsError) as e:
            GuideTrainingSettings(corpus=("schools",), **kw)
        assert e.value.option == option and f"--{option.replace('_', '-')}" in str(e.value)
    s = GuideTrainingSettings(corpus=("schools",), sample=5, sample_seed=2, validation_sample=3, validation_after=9)
    assert "--sample 5 --sample-seed 2 --validation-sample 3 --validation-after 9" in s.command("g.npz")


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ([], "needs --validation-sample"),
        (["--validation-sample", "3", "--sample", "4"], "sets --sample"),
        (["--validation-sample", "3", "--corpus", "schools", "ipa"], "one --corpus"),
        (["--validation-sample", "0"], "--validation-sample: "),
    ],
)
def test_the_command_refuses_what_a_curve_sets_itself(tmp_path, capsys, extra, message):
    """Each refusal is one line naming the option by its flag, before the output folder is made."""
    argv = ["train-guide", "--corpus", "schools", "--curve-sizes", "2", "5", "--out", str(tmp_path / "c"), *extra]
    assert ogm_ppl(argv) == 2
    assert message in capsys.readouterr().err and not (tmp_path / "c").exists()
    argv = ["train-guide", "--corpus", "schools", "--curve-sizes", "5", "2", "--validation-sample", "3"]
    assert ogm_ppl([*argv, "--out", str(tmp_path / "d")]) == 2
    assert "error: --curve-sizes: give ascending distinct sizes" in capsys.readouterr().err
    args = build_parser().parse_args(["train-guide", "--corpus", "schools", "--curve-sizes", "2", "--ship"])
    assert args.ship and args.curve_sizes == [2]
