"""experiments/unseen_by_distance.py: the bins split the unseen cells, and their NLLs weighted by their shares
give the NLL calibration.py scores for the same guide on the same map."""

import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def ubd():
    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        yield _load("unseen_by_distance_experiment", ROOT / "experiments" / "unseen_by_distance.py")
    finally:
        sys.path.remove(str(ROOT / "experiments"))
        sys.modules.pop("unseen_by_distance_experiment", None)


def test_bins_add_up_to_the_calibration_score(ubd, tmp_path):
    doc = ubd.main(["--guide", "houseexpo", "--test", "houseexpo", "--plans", "1", "--out", str(tmp_path)])
    rows = doc["rows"]
    assert [r["distance"] for r in rows] == [[0.0, 1.5], [1.5, 3.0], [3.0, 6.0], [6.0, None]]
    assert sum(r["share"] for r in rows) == pytest.approx(1.0, abs=1e-12)
    pooled = sum(r["share"] * r["nll_bits"] for r in rows)
    cal = ubd.calibration
    args = cal.parse_args(["--plans", "1"])
    scene = cal.make_scene(cal.heldout_maps("houseexpo", 1, args.window)[0], args)
    scored = cal.run_guide(scene, cal.guide_for("houseexpo"), args)["scores"]["unseen"]["nll_bits"]
    assert pooled == pytest.approx(scored, rel=1e-6)  # two ways to the same mean over one map's unseen cells
    assert json.loads((tmp_path / "unseen_by_distance.json").read_text())["rows"] == rows


def test_no_maps_is_refused(ubd, tmp_path):
    with pytest.raises(SystemExit, match="--plans must be at least 1"):
        ubd.main(["--plans", "0", "--out", str(tmp_path)])
