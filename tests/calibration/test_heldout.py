"""ogm_ppl.calibration.heldout: plan files as test maps, cropped as the corpora's are; a corpus plan given as a
file (its bytes, a touched-up copy, its HouseExpo layout) is refused; every bad file is named."""

import pytest

from ogm_ppl.calibration import LeakageError, check_plan_files, heldout, plan_file_maps
from ogm_ppl.datasets.plan_files import PlanFileError
from tests._plan_folder import write_plan_folder


def test_plan_files_are_cropped_as_the_corpora_are(tmp_path):
    d = write_plan_folder(tmp_path)
    maps = plan_file_maps([d], 5, 36, 0.025, "mine")
    assert [t.corpus for t in maps] == ["mine", "mine"] and all(t.truth.shape == (36, 36) for t in maps)
    assert sorted(t.plan for t in maps) == ["hall", "office"]
    assert [t.name for t in plan_file_maps([d], None, 36, 0.025)] == [t.name for t in maps]
    assert len(plan_file_maps([d], 1, 36, 0.025)) == 1


def test_every_bad_file_is_named_one_a_line():
    errors = [PlanFileError(f"f{i}", "wrong") for i in range(3)]
    assert str(heldout._every_error(errors)) == "f0: wrong\nf1: wrong\nf2: wrong"


def test_a_corpus_plan_given_as_a_file_is_refused(tmp_path):
    from ogm_ppl.datasets import floorplans as fp

    root = fp.floorplan_root()
    png = sorted((root / "houseexpo-subset100" / "png").glob("*.png"))
    if not png:
        pytest.skip("the HouseExpo corpus is not beside the repository")
    with pytest.raises(LeakageError, match="a plan of the floor-plan corpora"):
        check_plan_files([png[0]])
    (tmp_path / "copy.png").write_bytes(png[0].read_bytes())
    with pytest.raises(LeakageError, match="the same bytes as the corpus plan"):
        check_plan_files([tmp_path / "copy.png"])
    import numpy as np
    from PIL import Image

    px = np.asarray(Image.open(png[0]).convert("L")).copy()
    px[30, 30] = 255 - px[30, 30]  # touched up, turned and saved anew: other bytes, the same plan
    Image.fromarray(np.rot90(px)).save(tmp_path / "touched.png")
    with pytest.raises(LeakageError, match=r"its free space overlaps the houseexpo plan"):
        check_plan_files([tmp_path / "touched.png"])
    layout = tmp_path / f"{png[0].stem}.json"  # a HouseExpo layout under a corpus plan's id
    layout.write_text('{"verts": [[0, 0], [4, 0], [4, 3], [0, 3]]}')
    with pytest.raises(LeakageError, match="the layout of the houseexpo corpus's plan"):
        check_plan_files([layout])
    from ogm_ppl.datasets.plan_files import plan_files

    check_plan_files(plan_files([write_plan_folder(tmp_path)]))  # plans of no corpus pass
