"""ogm_ppl.studies.border_chain_probe: the tiles a table never counted, counted by hand, and the chain's record
on a small simulated dataset; experiments/border_chain_probe.py prints it."""

import numpy as np
import pytest

from ogm_ppl import Grid
from ogm_ppl.datasets.dataset_file import save_dataset
from ogm_ppl.datasets.simulate import simulate_scans
from ogm_ppl.priors.tables import tables_by_name
from ogm_ppl.studies.border_chain_probe import border_chain_probe, border_chain_probe_lines, unseen_tiles
from ogm_ppl.studies.errors import StudyOptionError
from tests._experiments import run_script


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """An experiment folder with one dataset: a 24 x 24 room with a wall, two scans."""
    root = tmp_path_factory.mktemp("probe")
    truth = np.zeros((24, 24), bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    truth[4:20, 12] = True
    grid = Grid(truth.shape, resolution=0.05)
    poses = np.array([[0.3, 0.3, 0.0], [0.9, 0.3, 0.0]])
    scans = simulate_scans(grid, truth, poses, np.linspace(0, 2 * np.pi, 45, endpoint=False), 1.0, 1.0, seed=1)
    (root / "datasets").mkdir()
    save_dataset(root / "datasets" / "d.npz", scans, grid=grid, truth=truth)
    np.savez(root / "datasets" / "d.eval.npz", truth=truth)
    return root, truth


def test_unseen_tiles_are_the_pairs_the_table_lacks(folder):
    _, truth = folder
    n, unseen = unseen_tiles(truth)
    assert n == 64 and 0 <= unseen <= n
    assert unseen_tiles(np.zeros((3, 3), bool)) == (1, 0)  # a free 3 x 3 room, walls round: counted
    checkers = (np.add.outer(np.arange(6), np.arange(6)) % 2).astype(bool)
    assert unseen_tiles(checkers) == (4, 4)  # no generated map is a checkerboard
    assert len(tables_by_name("generated").border_table().triples()[0]) > 0


def test_the_chain_is_recorded_sweep_by_sweep(folder):
    root, truth = folder
    doc = border_chain_probe(root, "d", sweeps=2)
    assert [s["sweep"] for s in doc["sweeps"]] == [1, 2] and doc["tiles"] == 64
    assert all(0 <= s["cells_unlike_truth"] <= truth.size for s in doc["sweeps"])
    assert np.isfinite(doc["truth"]["log_likelihood"])
    assert border_chain_probe(root, "d", sweeps=2)["sweeps"][1]["log_likelihood"] == doc["sweeps"][1]["log_likelihood"]
    lines = border_chain_probe_lines(doc)
    assert lines[0].startswith("true map: log prior") and lines[2].startswith("sweep 2: ")
    with pytest.raises(StudyOptionError, match="sweeps"):
        border_chain_probe(root, "d", sweeps=0)


def test_the_script_has_its_options():
    r = run_script("border_chain_probe.py", "--help")
    assert r.returncode == 0 and "--sweeps" in r.stdout and "--sigma" in r.stdout, r.stderr
