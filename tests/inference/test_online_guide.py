"""OnlineGuideMap: the guide's map kept per scan equals the guide's map of a model of every scan so far (the
features to one float32 ulp, the logits within the float32 bound of the float64 network) on a replay of a
simulated log and of a real log's first scans; only cells within the network's reach of a change are
recomputed; bad input is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.datasets import read_carmen, simulate_scans
from ogm_ppl.inference.online import OnlineGuideMap, replay_guide
from ogm_ppl.inference.variational import AmortisedGuide
from ogm_ppl.inference.variational.amortised_features import evidence_features
from ogm_ppl.priors import IndependentPrior
from tests.inference.variational.test_amortised_fast import exact_logits_and_bound

INTEL = Path(__file__).resolve().parents[3] / "shared" / "data" / "intel-lab" / "intel-corrected.log.gz"


def _part(scans: Scans, a: int, b: int) -> Scans:
    return Scans(scans.poses[a:b], scans.angles[a:b], scans.ranges[a:b], scans.max_range, valid=scans.valid[a:b])


def _scene(num_scans: int = 4, seed: int = 2):
    rng = np.random.default_rng(seed)
    H, W = 14, 17
    truth = np.zeros((H, W), bool)
    truth[0, :] = truth[-1, :] = truth[:, 0] = truth[:, -1] = True
    truth[5, 3:10] = truth[3:12, 12] = True
    grid = Grid((H, W), resolution=0.1)
    free = np.argwhere(~truth)
    pick = free[rng.choice(len(free), num_scans, replace=False)]
    poses = np.c_[(pick[:, 1] + 0.5) * 0.1, (pick[:, 0] + 0.5) * 0.1, rng.uniform(-np.pi, np.pi, num_scans)]
    scans = simulate_scans(grid, truth, poses, np.arange(24) * (2 * np.pi / 24), 1.0, 1.0, 3)
    return grid, scans


def _assert_equals_full(om: OnlineGuideMap, grid: Grid, scans: Scans, guide: AmortisedGuide) -> None:
    """The online features equal those of a model of ``scans`` (one float32 ulp: torch's vectorised and scalar
    ``log1p`` may round apart) and the online logits lie within the float32 bound of the float64 network on the
    online features; the map is the guide's marginals rule (pinned cells 0)."""
    model = OccupancyModel(grid, raycast(grid, scans), GaussianRange(1.0), IndependentPrior(0.5, grid.num_cells))
    full = evidence_features(model, None, guide.arch.delta, guide.arch.phase)
    x = om.features
    assert x.shape == full.shape
    torch.testing.assert_close(x, full, rtol=2.0**-23, atol=0.0)
    exact, bound = exact_logits_and_bound(guide.net, x[None], om.symmetrize)
    assert ((om.logits.reshape(grid.shape) - exact[0]).abs() <= bound[0]).all()
    assert torch.equal(om.pinned, model.known_free)
    assert np.array_equal(om.observed, model.rays.reached())
    p = om.probabilities
    assert (p[model.known_free] == 0).all()
    assert torch.equal(p[~model.known_free], torch.sigmoid(om.logits)[~model.known_free])


@pytest.mark.parametrize(("phase", "symmetrize"), [((0, 0), True), ((3, 3), False)])
def test_a_simulated_replay_equals_the_full_map_after_every_scan(phase, symmetrize):
    """Scans added one at a time, and then two at once: after each add the map is the guide's map of every scan
    so far; a cell farther than ``sum(dilations)`` from the cells a scan's rays reach keeps its logits."""
    grid, scans = _scene()
    guide = AmortisedGuide(channels=4, dilations=(1, 2, 1), phase=phase, seed=3)
    om = OnlineGuideMap(grid, guide, symmetrize=symmetrize)
    reach = sum(guide.arch.dilations)
    for i in range(scans.num_scans - 2):
        before = om.logits.clone()
        om.add_scans(_part(scans, i, i + 1))
        _assert_equals_full(om, grid, _part(scans, 0, i + 1), guide)
        touched = np.zeros(grid.num_cells, bool)
        touched[raycast(grid, _part(scans, i, i + 1)).cells] = True
        near = torch.nn.functional.max_pool2d(
            torch.from_numpy(touched.reshape(grid.shape)).float()[None, None], 2 * reach + 1, 1, reach
        )[0, 0].bool()
        far = ~near.reshape(-1)
        assert torch.equal(om.logits[far], before[far])
        assert 0 < om.recomputed <= int(near.sum())
    om.add_scans(_part(scans, scans.num_scans - 2, scans.num_scans))
    _assert_equals_full(om, grid, scans, guide)
    assert om.num_scans == scans.num_scans


@pytest.mark.skipif(not INTEL.exists(), reason="shared data not present")
def test_a_real_log_prefix_equals_the_full_map():
    """The Intel log's first scans (Section 6.2's 20 m rule) replayed on a small grid around the first pose: the
    replayed map equals the full map of the prefix, and the snapshots are the maps after their scans."""
    log = read_carmen(INTEL, max_usable_range=20.0)
    x0, y0 = log.scans.poses[0, :2]
    grid = Grid((20, 22), resolution=0.1, origin=(x0 - 1.05, y0 - 0.95))
    scans = _part(log.scans, 0, 4)
    guide = AmortisedGuide(channels=4, dilations=(1, 2, 1), phase=(0, 0), seed=1)
    r = replay_guide(grid, scans, guide, symmetrize=False, snapshot_every=2)
    _assert_equals_full(r.online, grid, scans, guide)
    assert [n for n, _ in r.snapshots] == [2, 4]
    assert np.array_equal(r.snapshots[-1][1], r.probabilities)
    assert (r.seconds_per_scan > 0).all()
    with torch.no_grad():
        model = OccupancyModel(grid, raycast(grid, scans), GaussianRange(1.0), IndependentPrior(0.5, grid.num_cells))
        q = guide.marginals(model).numpy()
    # both within the float32 bound of the float64 map; the bound is far below this
    assert np.abs(q - r.probabilities).max() < 1e-5


def test_bad_input_is_refused():
    grid, scans = _scene(2)
    guide = AmortisedGuide(channels=2, dilations=(1,), phase=(3, 3))
    with pytest.raises(ValueError, match="tile-phase"):
        OnlineGuideMap(grid, guide, symmetrize=True)
    with pytest.raises(ValueError, match="2D grid"):
        OnlineGuideMap(Grid((9,), 1.0), guide)
    om = OnlineGuideMap(grid, guide)
    with pytest.raises(TypeError, match="Scans"):
        om.add_scans(grid)  # type: ignore[arg-type]
    empty = Scans(scans.poses[:1], scans.angles[:1], scans.ranges[:1], scans.max_range, valid=np.zeros((1, 24), bool))
    with pytest.raises(ValueError, match="no reading"):
        om.add_scans(empty)
    with pytest.raises(ValueError, match="different grid"):
        om.add_rays(raycast(Grid((14, 17), resolution=0.2), _part(scans, 0, 1)))
    x = om.features  # nothing was added: no evidence, the inside channel, the tile phase
    assert om.num_scans == 0 and (x[:6] == 0).all() and (x[6] == 1).all() and (x[7:].sum(0) == 2).all()


def test_cli_map_online_amortised_writes_the_guides_map(tmp_path):
    """``ogm-ppl map --method amortised --online`` writes the map ``--method amortised`` writes (to float32
    rounding of logits of a few units: far below 1e-4 in probability), with snapshots and the report's record."""
    import json

    from ogm_ppl.cli import load_map, main
    from tests.test_cli import POSES, write_log

    log = write_log(tmp_path / "tiny.log")
    argv = ["map", str(log), "--resolution", "0.1", "--method", "amortised"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    assert main([*argv, "--online", "--snapshots", "2", "--out", str(tmp_path / "b")]) == 0
    a, b = load_map(tmp_path / "a" / "map.npz"), load_map(tmp_path / "b" / "map.npz")
    np.testing.assert_allclose(b["probabilities"], a["probabilities"], rtol=0, atol=1e-4)
    np.testing.assert_array_equal(b["observed"], a["observed"])
    report = json.loads((tmp_path / "b" / "report.json").read_text())
    assert report["method"]["kernel"] == "OnlineGuideMap" and report["method"]["online"]["scans"] == len(POSES)
    with np.load(tmp_path / "b" / "snapshots.npz", allow_pickle=False) as z:
        assert z["scans"].tolist() == [2, 4]
        np.testing.assert_array_equal(z["probabilities"][-1], b["probabilities"])


@pytest.mark.parametrize("online", [[], ["--online"]])
def test_cli_map_refuses_symmetrising_a_tile_phase_guide_by_its_parameter(tmp_path, capsys, online):
    from ogm_ppl.cli import main
    from tests.test_cli import write_log

    log = write_log(tmp_path / "tiny.log")
    argv = ["map", str(log), "--resolution", "0.1", "--method", "amortised", "--param", "symmetrize=true", *online]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ogm-ppl: error: --param symmetrize: a guide with tile-phase channels") and "\n" not in err
    assert not (tmp_path / "a").exists()


def test_the_thread_count_is_an_option_and_torchs_is_restored():
    grid, scans = _scene(2)
    guide = AmortisedGuide(channels=2, dilations=(1,), phase=(0, 0))
    with pytest.raises(ValueError, match="threads"):
        OnlineGuideMap(grid, guide, threads=0)
    before = torch.get_num_threads()
    a, b = OnlineGuideMap(grid, guide, threads=1), OnlineGuideMap(grid, guide, threads=2)
    for om in (a, b):
        om.add_scans(_part(scans, 0, 1))
    assert torch.get_num_threads() == before
    torch.testing.assert_close(a.logits, b.logits, rtol=0, atol=1e-4)  # float32 rounding of logits of a few units


def test_cli_map_refuses_snapshots_rarer_than_the_scans_it_maps(tmp_path, capsys):
    # every K-th scan of fewer than K scans is no snapshot: it wrote no snapshots.npz, and said nothing
    from ogm_ppl.cli import main
    from tests.test_cli import POSES, write_log

    log = write_log(tmp_path / "tiny.log")
    n = len(POSES)
    argv = ["map", str(log), "--resolution", "0.1", "--method", "amortised", "--online"]
    assert main([*argv, "--snapshots", str(n + 1), "--out", str(tmp_path / "a")]) == 2
    assert (
        capsys.readouterr().err.strip()
        == f"ogm-ppl: error: --snapshots {n + 1}: more than the {n} scans mapped (at most {n})"
    )
    assert not (tmp_path / "a").exists()
