"""Floor-plan corpora: readers on real files, fixed splits, the real-log exclusion list."""

import io
import re
import tarfile

import numpy as np
import pytest

from ogm_ppl.datasets import floorplans as fp

pytestmark = pytest.mark.skipif(
    not (fp.floorplan_root() / "ipa-room-segmentation-maps").is_dir(),
    reason="floor-plan corpora not present",
)
EVAL = re.compile(r"intel|freiburg", re.IGNORECASE)


def test_listing_and_split_sizes():
    assert len(fp.list_plans("houseexpo")) == 100
    ipa = fp.list_plans("ipa")
    assert "office_a" in ipa and "map" in ipa and not any("gt_segmentation" in n for n in ipa)
    d = fp.list_plans("dungeon")
    assert len(d) == 2500 and "train/1" in d and "test/img_6296" in d
    for corpus in ("houseexpo", "ipa"):
        names = fp.list_plans(corpus)
        test = [n for n in names if fp.split_of(corpus, n) == "test"]
        assert 0.1 < len(test) / len(names) < 0.4


def _present(corpus):
    try:
        fp.list_plans(corpus)
    except fp.CorpusNotFoundError:
        pytest.skip(f"{corpus} not present")


@pytest.mark.parametrize("corpus", fp.CORPORA)
def test_splits_disjoint_and_fixed(corpus):
    _present(corpus)
    tr, te = fp.training_plans(corpus, exclude_buildings=()), fp.heldout_plans(corpus)
    va = fp.validation_plans(corpus)  # R2V's validation list; empty elsewhere
    assert not set(tr) & set(te) and not set(va) & (set(tr) | set(te))
    assert set(tr) | set(te) | set(va) == set(fp.list_plans(corpus))
    # by building: no building on two sides
    sides = [{fp.building_of(corpus, n) for n in part} for part in (tr, te, va)]
    assert not sides[0] & sides[1] and not sides[2] & (sides[0] | sides[1])
    assert tr == fp.training_plans(corpus, exclude_buildings=())


def test_exclusion_list_effective():
    for corpus in fp.CORPORA:
        _present(corpus)
        assert not any(EVAL.search(n) for n in fp.training_plans(corpus))
    assert {"intel_map", "lab_intel", "Freiburg79_scan", "freiburg_building101"} <= {
        n for n in fp.list_plans("ipa") if fp.excluded(n)
    }
    # every plan of an excluded building is excluded (variants included)
    for n in fp.list_plans("ipa"):
        if fp.building_of("ipa", n) in ("intel", "freiburg79", "freiburg101", "freiburg52"):
            assert fp.excluded(n), n
    assert fp.building_of("ipa", "Freiburg79_scan_furnitures") == fp.building_of("ipa", "freiburg_building79")
    with pytest.raises(KeyError):
        fp.excluded("x", ["atlantis"])


def test_read_real_files():
    h = fp.load_plan("houseexpo", fp.list_plans("houseexpo")[0])
    assert h.resolution == 0.05 and h.known.all() and 0.05 < h.occupied_fraction < 0.8
    assert h.occupancy[0].all() and h.occupancy[:, -1].all()  # occupied exterior margin
    u = fp.load_plan("houseexpo", h.name, outside="unknown")
    assert u.shape == h.shape and not u.known.all()
    assert (u.occupancy[u.known] == h.occupancy[u.known]).all()
    assert not u.occupancy[~u.known].any()
    # at 1 cm the plan is 5x larger
    big = fp.load_plan("houseexpo", h.name, resolution=0.01, margin=None)
    assert big.shape[0] >= 5 * h.shape[0] - 2 * 20 * 5 - 10
    i = fp.load_plan("ipa", "lab_c_scan", outside="unknown")  # values {0, 205, 254}
    assert i.known.mean() < 0.95 and 0 < i.occupied_fraction < 0.3
    d = next(fp.iter_plans("dungeon", ["train/1", "test/img_6296"]))
    assert d.resolution is None and d.name == "train/1" and d.split == "train"
    with pytest.raises(ValueError, match="integer multiple"):
        fp.load_plan("ipa", "lab_a", resolution=0.07)
    with pytest.raises(KeyError):
        fp.load_plan("ipa", "no_such_map")


def test_rasterise_rules():
    free = np.zeros((12, 12), bool)
    free[4:8, 4:8] = True
    occ = ~free
    o, k = fp.rasterise(occ, free, margin=2, wall_cells=1, outside="unknown")
    assert o.shape == (8, 8)
    assert k[1:7, 1:7].all() and not k[0].any()  # wall ring 1 cell deep, then outside
    o2, k2 = fp.rasterise(occ, free, margin=2, outside="occupied")
    assert k2.all() and o2.sum() == 64 - 16
    # downsampling: any occupied pixel makes the cell occupied
    occ = np.zeros((4, 4), bool)
    occ[0, 0] = True
    o3, _ = fp.rasterise(occ, ~occ, factor=2, margin=None)
    assert o3.tolist() == [[True, False], [False, False]]


def test_unreadable_png_names_path(tmp_path):
    d = tmp_path / "ipa-room-segmentation-maps" / "test_maps"
    d.mkdir(parents=True)
    (d / "broken.png").write_bytes(b"\x89PNG not really")
    with pytest.raises(ValueError, match=r"broken\.png"):
        fp.load_plan("ipa", "broken", root=tmp_path)


def test_dungeon_bad_colour_names_member(tmp_path):
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.full((4, 4, 3), 10, np.uint8)).save(buf, format="PNG")
    tar = tmp_path / "dungeonmaps-synthetic" / "DungeonMaps_subset_train2000_test500.tar.gz"
    tar.parent.mkdir()
    with tarfile.open(tar, "w:gz") as tf:
        info = tarfile.TarInfo("DungeonMaps/train/7.png")
        info.size = buf.tell()
        buf.seek(0)
        tf.addfile(info, buf)
    with pytest.raises(ValueError, match=r"train/7\.png"):
        fp.load_plan("dungeon", "train/7", root=tmp_path)


def test_the_corpora_are_found_under_the_shared_data_folder_and_a_missing_one_says_where_it_looked(
    tmp_path, monkeypatch
):
    """``$OGM_PPL_DATA/floorplans`` holds the corpora (no machine path is assumed); a corpus that is not there is
    a :class:`CorpusNotFoundError` naming the folder and the variables, not an empty list."""
    monkeypatch.delenv("OGM_PPL_FLOORPLANS", raising=False)
    monkeypatch.setenv("OGM_PPL_DATA", str(tmp_path))
    assert fp.floorplan_root() == tmp_path / "floorplans"
    for corpus in fp.CORPORA:
        with pytest.raises(fp.CorpusNotFoundError, match=r"floorplans.* corpus is not there; set \$OGM_PPL_DATA"):
            fp.list_plans(corpus)
    monkeypatch.setenv("OGM_PPL_FLOORPLANS", str(tmp_path / "mine"))
    assert fp.floorplan_root() == tmp_path / "mine"
