"""Plans of any building from files: ROS maps and images -> FloorPlan, exactly as a corpus plan is built."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from ogm_ppl import Grid
from ogm_ppl.datasets.floorplans import rasterise
from ogm_ppl.datasets.plan_files import (
    MAX_PLAN_CELLS,
    PlanFileError,
    _resample,
    load_plan_file,
    plan_file_pieces,
    plan_files,
    plan_names,
)
from ogm_ppl.rosmap import save_ros_map


def _room(h: int = 30, w: int = 40) -> np.ndarray:
    """A grey image: a free room (255) with 2-pixel black walls, a black pillar, on a grey (205) background."""
    px = np.full((h + 8, w + 8), 205, np.uint8)
    px[4 : 4 + h, 4 : 4 + w] = 0
    px[6 : 2 + h, 6 : 2 + w] = 255
    px[12:15, 20:23] = 0
    return px


def test_image_at_its_own_pixel_size_is_the_corpus_rasterisation(tmp_path):
    px = _room()
    Image.fromarray(px).save(tmp_path / "room.png")
    plan = load_plan_file(tmp_path / "room.png", pixel_size=0.05)
    grey = px.astype(np.int16)
    unknown = np.abs(grey - 205) <= 3
    occ, known = rasterise((grey < 128) & ~unknown, (grey >= 128) & ~unknown)
    np.testing.assert_array_equal(plan.occupancy, occ)
    np.testing.assert_array_equal(plan.known, known)
    assert (plan.name, plan.building, plan.split, plan.resolution, plan.corpus) == (
        "room",
        "room",
        "test",
        0.05,
        "files",
    )
    # the room's free cells survive, the pillar stays occupied
    assert (~plan.occupancy).sum() == (px == 255).sum()


def test_ros_map_reads_as_the_image_it_was_saved_from(tmp_path):
    """One plan two ways: an image, and the same cells written as a ROS map (OccupancyGrid rows bottom-up)."""
    px = _room()
    Image.fromarray(px).save(tmp_path / "room.png")
    from_image = load_plan_file(tmp_path / "room.png", pixel_size=0.05)
    grey = px.astype(np.int16)
    p = np.where(grey < 128, 1.0, 0.0)
    unknown = np.abs(grey - 205) <= 3
    grid = Grid(px.shape, resolution=0.05)
    # ogm_ppl cell (row, col) is image pixel (rows - 1 - row, col): flip the image rows into grid order
    save_ros_map(tmp_path / "ros" / "room.yaml", p[::-1].ravel(), grid, unknown=unknown[::-1].ravel(), sidecar=False)
    from_ros = load_plan_file(tmp_path / "ros" / "room.yaml")
    np.testing.assert_array_equal(from_ros.occupancy, from_image.occupancy)
    np.testing.assert_array_equal(from_ros.known, from_image.known)
    again = load_plan_file(tmp_path / "ros" / "room.yaml", pixel_size=0.1)  # an image's pixel size: not a YAML's
    np.testing.assert_array_equal(again.occupancy, from_image.occupancy)


@pytest.mark.parametrize("f", [2.0, 3.0, 2.5, 0.5])
def test_resample_keeps_every_occupied_pixel_and_is_the_block_or_for_integer_factors(f):
    rng = np.random.default_rng(1)
    occ = rng.random((37, 29)) < 0.1
    free = ~occ & (rng.random(occ.shape) < 0.9)
    o, fr = _resample(occ, free, f)
    assert not (o & fr).any()
    if f >= 1:
        assert o.shape == (int(np.ceil(37 / f)), int(np.ceil(29 / f)))
        starts_r = np.floor(np.arange(o.shape[0]) * f).astype(int)
        starts_c = np.floor(np.arange(o.shape[1]) * f).astype(int)
        rows = np.searchsorted(starts_r, np.arange(37), side="right") - 1
        cols = np.searchsorted(starts_c, np.arange(29), side="right") - 1
        want = np.zeros(o.shape, bool)
        np.logical_or.at(want, (rows[:, None], cols[None, :]), occ)
        np.testing.assert_array_equal(o, want)  # each pixel lands in the cell holding its top-left corner
        if f == int(f):
            k = int(f)
            pad = np.pad(occ, ((0, -37 % k), (0, -29 % k)))
            np.testing.assert_array_equal(o, pad.reshape(o.shape[0], k, o.shape[1], k).any((1, 3)))
    else:  # finer cells: each takes the pixel under its centre
        assert o.shape == (74, 58)
        np.testing.assert_array_equal(o[::2, ::2], occ)
        np.testing.assert_array_equal(o[1::2, 1::2], occ)


def test_bad_plan_files_name_the_file(tmp_path):
    Image.fromarray(_room()).save(tmp_path / "room.png")
    with pytest.raises(PlanFileError, match=r"room\.png: an image has no scale"):
        load_plan_file(tmp_path / "room.png")
    with pytest.raises(PlanFileError, match="positive number"):
        load_plan_file(tmp_path / "room.png", pixel_size=-1)
    with pytest.raises(PlanFileError, match="no such plan file"):
        load_plan_file(tmp_path / "none.png", pixel_size=0.05)
    (tmp_path / "junk.png").write_bytes(b"not an image")
    with pytest.raises(PlanFileError, match=r"junk\.png: unreadable image"):
        load_plan_file(tmp_path / "junk.png", pixel_size=0.05)
    Image.fromarray(np.zeros((20, 20), np.uint8)).save(tmp_path / "black.png")
    with pytest.raises(PlanFileError, match=r"black\.png: no free pixel"):
        load_plan_file(tmp_path / "black.png", pixel_size=0.05)
    (tmp_path / "bad.yaml").write_text("image: missing.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n")
    with pytest.raises(PlanFileError, match=r"bad\.yaml: missing required key"):
        load_plan_file(tmp_path / "bad.yaml")
    keys = "occupied_thresh: 0.65\nfree_thresh: 0.196\nnegate: 0\n"
    (tmp_path / "bad.yaml").write_text("image: missing.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n" + keys)
    with pytest.raises(PlanFileError, match=r"missing\.pgm"):
        load_plan_file(tmp_path / "bad.yaml")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(PlanFileError, match="not a plan file"):
        load_plan_file(tmp_path / "notes.txt", pixel_size=0.05)
    side = int(np.sqrt(MAX_PLAN_CELLS)) // 100 + 1  # pixels of 1 m at 0.01 m a cell: over the limit
    Image.fromarray(np.full((side, side), 255, np.uint8)).save(tmp_path / "big.png")
    with pytest.raises(PlanFileError, match="over the limit"):
        load_plan_file(tmp_path / "big.png", pixel_size=1.0, resolution=0.01)
    with pytest.raises(PlanFileError, match=r"no free cell left .*: is the pixel size right\?"):
        load_plan_file(tmp_path / "room.png", pixel_size=0.0005)  # pixels of 0.5 mm: walls fill every cell
    with pytest.raises(PlanFileError, match=r"a folder, not a plan file: plan_files\(\[folder\]\)"):
        load_plan_file(tmp_path, pixel_size=0.05)


def test_plan_files_and_names(tmp_path, monkeypatch):
    px = _room()
    for d in ("a", "b"):
        grid = Grid(px.shape, resolution=0.05)
        save_ros_map(tmp_path / d / "map.yaml", np.where(px < 128, 1.0, 0.0).ravel(), grid, sidecar=False)
    Image.fromarray(px).save(tmp_path / "a" / "extra.png")
    (tmp_path / "a" / "readme.txt").write_text("not a plan")
    files = plan_files([tmp_path / "a", tmp_path / "b" / "map.yaml"])
    # the PGM the YAML names is read through the YAML only; the text file is not a plan
    assert [f.name for f in files] == ["extra.png", "map.yaml", "map.yaml"]
    assert plan_names(files) == ["a/extra", "a/map", "b/map"]
    assert plan_names(files[:2]) == ["extra", "map"]
    assert plan_file_pieces(files[1]) == [files[1], (tmp_path / "a" / "map.pgm").resolve()]  # the YAML, its image
    assert plan_file_pieces(files[0]) == [files[0]]
    # a YAML given by a relative path names its image relative too (records hold no machine's folder)
    monkeypatch.chdir(tmp_path)
    assert plan_file_pieces(Path("a/map.yaml")) == [Path("a/map.yaml"), Path("a/map.pgm")]
    with pytest.raises(PlanFileError, match="no such file or folder"):
        plan_files([tmp_path / "nowhere"])
    with pytest.raises(PlanFileError, match="not a plan file"):
        plan_files([tmp_path / "a" / "readme.txt"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(PlanFileError, match="no plan file"):
        plan_files([tmp_path / "empty"])


def _layout(tmp_path, verts, name="house.json", **extra):
    import json

    path = tmp_path / name
    path.write_text(json.dumps({"id": name.removesuffix(".json"), "verts": verts, **extra}))
    return path


def test_houseexpo_layout_renders_as_houseexpo_renders_it(tmp_path):
    """An L-shaped outline (metres): its rendering at 1 cm with 25 pixels around it, and the plan equals the
    corpus pipeline run on that rendering saved as a PNG (what the houseexpo corpus's PNGs are)."""
    from ogm_ppl.datasets.plan_files import render_layout

    verts = [[1.0, 2.0], [5.0, 2.0], [5.0, 4.0], [3.0, 4.0], [3.0, 6.5], [1.0, 6.5]]
    path = _layout(tmp_path, verts, room_category={"bedroom": [[1.0, 2.0, 5.0, 4.0]]})
    img = render_layout(path)
    assert img.shape == (450 + 50, 400 + 50)  # (6.5 - 2) m x (5 - 1) m at 100 px a metre, plus 25 px a side
    assert img[25 + 10, 25 + 10] == 255 and img[25 + 300, 25 + 300] == 0  # inside the L; in its notch
    assert img[:25].max() == 0 and img[:, :25].max() == 0  # the exterior band
    inside = (img == 255).sum()
    assert abs(inside - (400 * 200 + 200 * 250)) <= 2 * (400 + 450) + 4  # the area, up to the outline's pixels
    Image.fromarray(img).save(tmp_path / "house.png")
    from_png = load_plan_file(tmp_path / "house.png", pixel_size=0.01)
    plan = load_plan_file(path)
    np.testing.assert_array_equal(plan.occupancy, from_png.occupancy)
    assert plan.name == "house" and plan.resolution == 0.05


def test_bad_layouts_name_the_file_and_line(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text('{"verts": [[0, 0], [1, 0],\n [1, 1]')
    with pytest.raises(PlanFileError, match=r"bad\.json: not JSON text \(line 2"):
        load_plan_file(p)
    (tmp_path / "other.json").write_text('{"rooms": []}')
    with pytest.raises(PlanFileError, match=r"other\.json: not a HouseExpo layout: no 'verts'"):
        load_plan_file(tmp_path / "other.json")
    with pytest.raises(PlanFileError, match="pairs of finite numbers"):
        load_plan_file(_layout(tmp_path, [[0, 0], [1, 0]], name="two.json"))
    with pytest.raises(PlanFileError, match="pairs of finite numbers"):
        load_plan_file(_layout(tmp_path, [[0, 0], [1, "a"], [1, 1]], name="text.json"))
    with pytest.raises(PlanFileError, match="over the limit"):
        load_plan_file(_layout(tmp_path, [[0, 0], [500, 0], [500, 500]], name="huge.json"))


def test_a_pixel_size_a_whole_fraction_of_the_cell_gives_whole_blocks(tmp_path):
    """A pixel size written to six digits (0.0166667 m, 3 pixels a 0.05 m cell: 0.05 / 0.0166667 = 2.999994) gives
    whole blocks of pixels all the same (the corpora's integer downsampling)."""
    rng = np.random.default_rng(2)
    px = np.where(rng.random((100, 120)) < 0.05, 0, 255).astype(np.uint8)
    px[:, :3] = 0
    Image.fromarray(px).save(tmp_path / "speckle.png")
    occ_px, free_px = px < 128, px >= 128
    for pixel_size, k in ((0.01, 5), (0.0166667, 3), (0.00833333, 6), (0.025, 2)):
        plan = load_plan_file(tmp_path / "speckle.png", pixel_size=pixel_size)
        occ, _ = rasterise(occ_px, free_px, k)
        np.testing.assert_array_equal(plan.occupancy, occ)


def test_16_bit_grey_and_transparent_images(tmp_path):
    """A 16-bit plan reads as its 8-bit copy (Pillow's own conversion would clip every value over 255 to white);
    transparent pixels are unknown."""
    px = _room()
    Image.fromarray(px).save(tmp_path / "room8.png")
    Image.fromarray(px.astype(np.uint16) * 257).save(tmp_path / "room16.png")
    assert Image.open(tmp_path / "room16.png").mode.startswith("I")
    a = load_plan_file(tmp_path / "room8.png", pixel_size=0.05)
    b = load_plan_file(tmp_path / "room16.png", pixel_size=0.05)
    np.testing.assert_array_equal(a.occupancy, b.occupancy)
    np.testing.assert_array_equal(a.known, b.known)
    dark = np.where(px == 0, 1000, 65535).astype(np.uint16)  # walls at 1000 / 65535: dark, though over 255
    dark[px == 205] = 205 * 257
    Image.fromarray(dark).save(tmp_path / "dark16.png")
    np.testing.assert_array_equal(load_plan_file(tmp_path / "dark16.png", pixel_size=0.05).occupancy, a.occupancy)
    # RGBA: the grey background drawn transparent instead reads as the same unknown cells
    rgba = np.zeros((*px.shape, 4), np.uint8)
    rgba[..., :3] = np.where(px == 205, 0, px)[..., None]
    rgba[..., 3] = np.where(px == 205, 0, 255)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "room_rgba.png")
    c = load_plan_file(tmp_path / "room_rgba.png", pixel_size=0.05, outside="unknown")
    ref = load_plan_file(tmp_path / "room8.png", pixel_size=0.05, outside="unknown")
    np.testing.assert_array_equal(c.known, ref.known)
    np.testing.assert_array_equal(c.occupancy, ref.occupancy)


def test_names_stay_distinct_and_a_file_is_read_once(tmp_path):
    import json

    Image.fromarray(_room()).save(tmp_path / "house.png")
    (tmp_path / "house.json").write_text(json.dumps({"verts": [[0, 0], [4, 0], [4, 3], [0, 3]]}))
    (tmp_path / "x").mkdir()
    files = plan_files([tmp_path, tmp_path / "x" / ".." / "house.png"])  # the same PNG twice: read once
    assert sorted(plan_names(files)) == ["house.json", "house.png"]
    with pytest.raises(PlanFileError, match="given twice"):
        plan_names([tmp_path / "house.png", tmp_path / "x" / ".." / "house.png"])


def test_a_yaml_naming_a_missing_image_is_named(tmp_path):
    keys = "resolution: 0.05\norigin: [0.0, 0.0, 0.0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\nnegate: 0\n"
    (tmp_path / "map.yaml").write_text("image: nosuch.pgm\n" + keys)
    with pytest.raises(PlanFileError, match=r"map\.yaml: its image .*nosuch\.pgm"):
        load_plan_file(tmp_path / "map.yaml")


def test_corpus_copy_finds_corpus_plans_and_passes_others(tmp_path):
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.datasets.plan_files import corpus_copy

    Image.fromarray(_room()).save(tmp_path / "room.png")
    assert corpus_copy(tmp_path / "room.png", root=tmp_path / "no_corpora") is None  # no corpora: nothing to copy
    root = fp.floorplan_root()
    names = fp.list_plans("ipa", root) if root.is_dir() else []
    if not names:
        pytest.skip("the IPA corpus is not beside the repository")
    assert corpus_copy(tmp_path / "room.png") is None
    src = fp.plan_image_path("ipa", names[0])
    assert "a plan of the floor-plan corpora" in corpus_copy(src)
    px = np.asarray(Image.open(src).convert("L"))
    Image.fromarray(px[:, ::-1]).save(tmp_path / "flipped.png")  # flipped and saved anew
    assert f"overlaps the ipa plan {names[0]}'s" in corpus_copy(tmp_path / "flipped.png")
