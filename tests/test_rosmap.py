"""ROS map_server export/import: pixel layout, thresholds, modes, negate, YAML types, malformed files."""

import json
import math
import re
import warnings

import numpy as np
import pytest
import torch

from ogm_ppl.grid import Grid
from ogm_ppl.inference.log_odds import LogOddsMap
from ogm_ppl.rosmap import (
    RosMapError,
    from_occupancy_grid,
    load_ros_map,
    save_ros_map,
    to_occupancy_grid,
)

THRESH = {"ros1": (0.65, 0.196), "nav2": (0.65, 0.25)}


def _map(rows=4, cols=7, seed=0):
    """An asymmetric map with a non-zero origin, probabilities spread over [0, 1], some unknown."""
    rng = np.random.default_rng(seed)
    grid = Grid((rows, cols), resolution=0.25, origin=(-1.5, 2.75))
    p = rng.uniform(0, 1, grid.num_cells)
    p[:5] = [0.0, 1.0, 0.65, 0.196, 0.25]  # exact thresholds stay on the unknown side
    unknown = rng.uniform(size=grid.num_cells) < 0.2
    unknown[:5] = False
    return grid, p, unknown


def _read_pgm(path):
    """Independent minimal P5 reader (header without comments after the first line's comment)."""
    data = path.read_bytes()
    lines = data.split(b"\n", 4)
    assert lines[0] == b"P5" and lines[1].startswith(b"#")
    w, h = map(int, lines[2].split())
    assert lines[3] == b"255"
    px = np.frombuffer(lines[4], dtype=np.uint8)
    assert px.size == w * h
    return px.reshape(h, w)


def _expected(p, unknown, mode, occ, free, png=False, grey=205):
    """map_server's reading of our export, computed from the documented formulas (Nav2 flavour)."""
    if mode == "trinary":
        out = np.where(p > occ, 100, np.where(p < free, 0, -1))
    else:
        x = np.floor(255 * (1 - p) + 0.5)
        x[unknown] = grey
        q = (255 - x) / 255
        out = np.where(q > occ, 100, np.where(q < free, 0, np.rint(100 * (q - free) / (occ - free))))
        if not png:
            return out.astype(np.int8)
    out[unknown] = -1
    return out.astype(np.int8)


@pytest.mark.parametrize("negate", [False, True])
@pytest.mark.parametrize("mode", ["trinary", "scale"])
@pytest.mark.parametrize("thresholds", ["ros1", "nav2"])
def test_round_trip(tmp_path, thresholds, mode, negate):
    grid, p, unknown = _map()
    occ, free = THRESH[thresholds]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scale + PGM warns about unknown cells
        files = save_ros_map(
            tmp_path / "sub" / "map.yaml", p, grid, unknown=unknown, mode=mode, thresholds=thresholds, negate=negate
        )
    m = load_ros_map(files.yaml)
    assert m.grid == grid and m.grid.shape == (4, 7)
    assert m.settings.resolution == 0.25 and m.settings.origin == (-1.5, 2.75, 0.0)
    assert (m.settings.occupied_thresh, m.settings.free_thresh) == (occ, free)
    assert m.settings.negate is negate and m.settings.mode == mode
    assert m.occupancy.dtype == np.int8
    np.testing.assert_array_equal(m.occupancy, _expected(p, unknown, mode, occ, free))
    if mode == "trinary":
        np.testing.assert_array_equal(m.occupancy, to_occupancy_grid(p, unknown, thresholds))
    np.testing.assert_array_equal(m.probabilities, p)
    np.testing.assert_array_equal(m.unknown, unknown)
    # the pixels themselves: row 0 of the image is the top row (max y) of the grid
    px = _read_pgm(files.image).astype(int)
    plain = 255 - px if negate else px
    grid_img = plain[::-1].reshape(-1)
    if mode == "trinary":
        u = 205 if thresholds == "ros1" else files.unknown_value
        want = np.where(p > occ, 0, np.where(p < free, 254, u))
        want[unknown] = u
    else:
        want = np.floor(255 * (1 - p) + 0.5)
        want[unknown] = 205
    np.testing.assert_array_equal(grid_img, want)
    assert not list(tmp_path.rglob("*.tmp"))


@pytest.mark.parametrize("thresholds", ["ros1", "nav2"])
def test_scale_png_marks_unknown_transparent(tmp_path, thresholds):
    grid, p, unknown = _map()
    occ, free = THRESH[thresholds]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning: PNG has alpha
        files = save_ros_map(
            tmp_path / "m", p, grid, unknown=unknown, mode="scale", thresholds=thresholds, image_format="png"
        )
    assert files.image.name == "m.png" and files.yaml.name == "m.yaml"
    m = load_ros_map(files.yaml)
    np.testing.assert_array_equal(m.occupancy, _expected(p, unknown, "scale", occ, free, True, files.unknown_value))
    m1 = load_ros_map(files.yaml, flavor="ros1")  # ROS 1: int(1 + 98 r) in the middle band
    q = (255 - np.floor(255 * (1 - p) + 0.5)) / 255
    mid = (q >= free) & (q <= occ) & ~unknown
    np.testing.assert_array_equal(m1.occupancy[mid], np.trunc(1 + 98 * (q[mid] - free) / (occ - free)))
    assert np.all(m1.occupancy[unknown] == -1)


def test_cell_lands_on_the_right_pixel_and_world_point(tmp_path):
    grid = Grid((3, 5), resolution=0.1, origin=(2.0, -7.0))  # asymmetric, non-zero origin
    p = np.full(grid.num_cells, 0.05)
    cell = (0, 4)  # bottom row, last column: lower-right corner of the picture
    p[grid.flat_index(np.array(cell))] = 0.99
    xy = grid.cell_to_world(np.array([cell]))[0]
    files = save_ros_map(tmp_path / "m.yaml", p, grid, sidecar=False)
    px = _read_pgm(files.image)
    assert px.shape == (3, 5)
    assert px[2, 4] == 0 and np.sum(px == 0) == 1  # image row 2 of 3 = bottom
    m = load_ros_map(files.yaml)
    assert m.probabilities is None and m.sidecar_path is None
    (k,) = np.flatnonzero(m.occupancy == 100)
    # ROS: data index k -> (x, y) = origin + ((k % width) + 0.5, (k // width) + 0.5) * resolution
    ox, oy, _ = m.settings.origin
    ros_xy = (ox + (k % 5 + 0.5) * 0.1, oy + (k // 5 + 0.5) * 0.1)
    np.testing.assert_allclose(ros_xy, xy)
    np.testing.assert_allclose(m.grid.cell_to_world(np.array([[k // 5, k % 5]]))[0], xy)
    assert tuple(m.grid.world_to_cell(xy[None])[0]) == cell


def test_occupancy_grid_conversion():
    p = np.array([[0.0, 0.3, 0.7], [1.0, 0.2, np.nan]])  # grid-shaped: flattened, not flipped
    unk = np.array([[False, False, False], [False, True, False]])
    tri = to_occupancy_grid(p, unk, "nav2")
    assert tri.dtype == np.int8 and tri.shape == (6,)
    assert tri.tolist() == [0, -1, 100, 100, -1, -1]
    assert to_occupancy_grid(p, unk, "ros1").tolist() == [0, -1, 100, 100, -1, -1]
    assert to_occupancy_grid([0.1, 0.19, 0.2], thresholds="ros1").tolist() == [0, 0, -1]
    assert to_occupancy_grid(p, mode="linear").tolist() == [0, 30, 70, 100, 20, -1]
    assert to_occupancy_grid([0.45, 0.7, 0.1], thresholds=(0.65, 0.25), mode="scale").tolist() == [
        50,
        100,
        0,
    ]
    assert to_occupancy_grid(torch.tensor([0.9, 0.1])).tolist() == [100, 0]
    q, u = from_occupancy_grid(np.array([0, 37, 100, -1], dtype=np.int8))
    assert q.tolist() == [0.0, 0.37, 1.0, 0.5] and u.tolist() == [False, False, False, True]
    r = np.random.default_rng(1).uniform(size=50)
    back, u = from_occupancy_grid(to_occupancy_grid(r, mode="linear"))
    assert not u.any() and np.max(np.abs(back - r)) <= 0.005 + 1e-12
    with pytest.raises(ValueError):
        to_occupancy_grid([1.5])
    with pytest.raises(ValueError):
        to_occupancy_grid([0.5], thresholds=(0.2, 0.6))
    with pytest.raises(ValueError):
        from_occupancy_grid(np.array([0.5]))


def test_yaml_text_and_types(tmp_path):
    grid = Grid((2, 3), resolution=0.05, origin=(-1.5, 2.25))
    files = save_ros_map(tmp_path / "lab map", np.full(6, 0.1), grid, thresholds="nav2")
    text = files.yaml.read_text()
    assert text == (
        'image: "lab map.pgm"\nmode: trinary\nresolution: 0.05\norigin: [-1.5, 2.25, 0.0]\n'
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n"
    )
    kv = dict(line.split(": ", 1) for line in text.splitlines())
    yaml11_float = re.compile(r"[-+]?[0-9]+\.[0-9]*([eE][-+][0-9]+)?")  # PyYAML's (YAML 1.1) float
    for key in ("resolution", "occupied_thresh", "free_thresh"):
        assert yaml11_float.fullmatch(kv[key]), key
    origin = json.loads(kv["origin"])  # a flow list of numbers is also JSON
    assert len(origin) == 3 and all(isinstance(v, float) for v in origin)
    assert all(yaml11_float.fullmatch(v.strip()) for v in kv["origin"][1:-1].split(","))
    assert re.fullmatch(r"[01]", kv["negate"])
    assert kv["mode"] in ("trinary", "scale")
    assert json.loads(kv["image"]) == "lab map.pgm"
    # tiny resolutions keep a dot so YAML 1.1 readers still see a float
    g2 = Grid((1, 2), resolution=1e-5, origin=(1e20, 0.0))
    t2 = save_ros_map(tmp_path / "tiny", np.zeros(2), g2).yaml.read_text()
    assert "resolution: 1.0e-05\n" in t2 and "origin: [1.0e+20, 0.0, 0.0]" in t2
    assert load_ros_map(tmp_path / "tiny.yaml").grid == g2


def test_nav2_thresholds_keep_unknown_unknown(tmp_path):
    grid = Grid((1, 3))
    p, unk = np.array([0.9, 0.1, 0.5]), np.array([False, False, True])
    files = save_ros_map(tmp_path / "a", p, grid, unknown=unk, thresholds="nav2")
    assert files.unknown_value != 205  # 205 reads back as free under free_thresh 0.25
    assert load_ros_map(files.yaml).occupancy.tolist() == [100, 0, -1]
    with pytest.warns(UserWarning, match="reads back as known"):
        f205 = save_ros_map(tmp_path / "b", p, grid, unknown=unk, thresholds="nav2", unknown_value=205)
    assert load_ros_map(f205.yaml).occupancy.tolist() == [100, 0, 0]  # what Nav2's map_server does
    with pytest.warns(UserWarning, match="alpha"):
        save_ros_map(tmp_path / "c", p, grid, unknown=unk, mode="scale")


def test_log_odds_map_and_1d_grid(tmp_path):
    grid = Grid.line(4, resolution=0.5)
    lo = LogOddsMap(grid, torch.tensor([3.0, -3.0, 0.0, 0.0]), torch.tensor([True, True, True, False]))
    files = save_ros_map(tmp_path / "line.yml", lo)
    m = load_ros_map(files.yaml)
    assert m.grid == grid and m.pixels.shape == (1, 4)
    assert m.occupancy.tolist() == [100, 0, -1, -1]
    assert m.unknown.tolist() == [False, False, False, True]
    np.testing.assert_allclose(m.probabilities, torch.sigmoid(lo.log_odds).numpy())


def test_stale_sidecar_is_ignored(tmp_path):
    grid = Grid((2, 2))
    save_ros_map(tmp_path / "m", np.full(4, 0.9), grid)
    save_ros_map(tmp_path / "m", np.full(4, 0.1), grid, sidecar=False)
    with pytest.warns(UserWarning, match="stale"):
        m = load_ros_map(tmp_path / "m.yaml")
    assert m.probabilities is None and m.occupancy.tolist() == [0, 0, 0, 0]


def _write(tmp_path, yaml_text, image=None, name="map"):
    if image is None:
        image = b"P5\n2 2\n255\n" + bytes([0, 254, 205, 254])
    (tmp_path / f"{name}.pgm").write_bytes(image)
    y = tmp_path / f"{name}.yaml"
    y.write_text(yaml_text)
    return y


GOOD = (
    "image: map.pgm\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
)


def test_accepts_what_map_server_accepts(tmp_path):
    text = (
        "# saved by hand\r\n---\r\nimage:   'map.pgm'   # quoted\r\nresolution: 0.1\r\n"
        "origin:\r\n  - 1\r\n  - -2.5\r\n  - 0\r\nnegate: false\r\noccupied_thresh: .65\r\n"
        "free_thresh: 1.96e-1\r\nextra_key: whatever\r\n"
    )
    img = b"P2\n# a comment\n2 2\n15\n0 15\n11 15\n"  # ASCII PGM, maxval 15
    m = load_ros_map(_write(tmp_path, text, img))
    assert m.grid == Grid((2, 2), resolution=0.1, origin=(1.0, -2.5))
    assert m.settings.mode == "trinary" and m.settings.extra == {"extra_key": "whatever"}
    # image rows [[0, 255], [187, 255]] -> bottom row first: [187 -> -1, 255 -> 0], [0 -> 100, 255 -> 0]
    assert m.occupancy.tolist() == [-1, 0, 100, 0]
    m2 = load_ros_map(_write(tmp_path, GOOD.replace("negate: 0", "negate: 1"), name="map"))
    # negate: p = x / 255; image [[0, 254], [205, 254]], bottom row first; 205 -> 0.80 > 0.65
    assert m2.occupancy.tolist() == [100, 100, 0, 100]


def test_a_16_bit_pgm_reads_as_its_8_bit_scaling(tmp_path):
    """Two bytes a sample, most significant first (netpbm), scaled by maxval to 8 bits as other maxvals are:
    the same map as the 8-bit ASCII image of the test above."""
    text = (
        "image: map.pgm\nresolution: 0.1\norigin: [1, -2.5, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    px = np.array([[0, 65535], [48059, 65535]], dtype=">u2")
    m = load_ros_map(_write(tmp_path, text, b"P5\n2 2\n65535\n" + px.tobytes()))
    assert m.occupancy.tolist() == [-1, 0, 100, 0]


MALFORMED = {
    "missing key": GOOD.replace("resolution: 0.1\n", ""),
    "resolution not a number": GOOD.replace("0.1", "fast"),
    "resolution nan": GOOD.replace("0.1", ".nan"),
    "resolution zero": GOOD.replace("0.1", "0.0"),
    "origin too short": GOOD.replace("[0.0, 0.0, 0.0]", "[0.0, 0.0]"),
    "origin infinite": GOOD.replace("[0.0, 0.0, 0.0]", "[0.0, .inf, 0.0]"),
    "origin scalar": GOOD.replace("[0.0, 0.0, 0.0]", "0.0"),
    "origin unterminated": GOOD.replace("[0.0, 0.0, 0.0]", "[0.0, 0.0, 0.0"),
    "negate word": GOOD.replace("negate: 0", "negate: maybe"),
    "negate float": GOOD.replace("negate: 0", "negate: 0.5"),
    "mode unknown": GOOD + "mode: fancy\n",
    "thresholds reversed": GOOD.replace("0.65", "0.1"),
    "duplicate key": GOOD + "resolution: 0.2\n",
    "nested mapping": GOOD + "meta:\n  author: me\n",
    "not key value": GOOD + "just some words\n",
    "image missing": GOOD.replace("map.pgm", "nothere.pgm"),
    "image empty": GOOD.replace("map.pgm", "''"),
    "image list": GOOD.replace("image: map.pgm", "image: [a, b]"),
}
BAD_IMAGES = {
    "bad magic": b"P7\n2 2\n255\n\0\0\0\0",
    "bad header": b"P5\n2 x\n255\n\0\0\0\0",
    "truncated header": b"P5\n2 2\n",
    "truncated data": b"P5\n2 2\n255\n\0\0\0",
    "a row more than the header says": b"P5\n2 2\n255\n" + bytes(6),
    "values after the ASCII pixels": b"P2\n2 1\n255\n3 4 5\n",
    "maxval past 16 bits": b"P5\n2 2\n65536\n" + bytes(8),
    "16-bit data cut short": b"P5\n2 2\n65535\n" + bytes(7),
    "zero width": b"P5\n0 2\n255\n",
    "value above maxval": b"P2\n2 1\n15\n3 16\n",
    "not an image": b"hello, world",
    "empty file": b"",
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_yaml_raises(tmp_path, case):
    y = _write(tmp_path, MALFORMED[case])
    with pytest.raises(RosMapError) as e:
        load_ros_map(y)
    target = "nothere.pgm" if case == "image missing" else str(y)
    assert target in str(e.value)
    assert isinstance(e.value, ValueError)


@pytest.mark.parametrize("case", sorted(BAD_IMAGES))
def test_malformed_image_raises(tmp_path, case):
    y = _write(tmp_path, GOOD, BAD_IMAGES[case])
    with pytest.raises(RosMapError) as e:
        load_ros_map(y)
    assert str(tmp_path / "map.pgm") in str(e.value)


def test_trailing_whitespace_after_the_pixels_is_allowed(tmp_path):
    y = _write(tmp_path, GOOD, b"P5\n2 2\n255\n" + bytes([0, 255, 254, 0]) + b"\n")
    assert load_ros_map(y).grid.num_cells == 4
    with pytest.raises(RosMapError, match="PGM has 2 pixel bytes after the 2 x 2 its header states"):
        load_ros_map(_write(tmp_path, GOOD, b"P5\n2 2\n255\n" + bytes(6)))


def test_missing_yaml_and_bad_sidecar_raise(tmp_path):
    with pytest.raises(RosMapError, match="not found") as e:
        load_ros_map(tmp_path / "none.yaml")
    assert str(tmp_path / "none.yaml") in str(e.value)
    y = _write(tmp_path, GOOD)
    (tmp_path / "map.npz").write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(RosMapError, match="sidecar") as e:
        load_ros_map(y)
    assert str(tmp_path / "map.npz") in str(e.value)
    (tmp_path / "bin.yaml").write_bytes(b"image: \xff\xfe\n")
    with pytest.raises(RosMapError, match="UTF-8"):
        load_ros_map(tmp_path / "bin.yaml")


def test_save_validates_inputs(tmp_path):
    grid = Grid((2, 2))
    with pytest.raises(ValueError, match="cells"):
        save_ros_map(tmp_path / "m", np.zeros(3), grid)
    with pytest.raises(ValueError, match="bool"):
        save_ros_map(tmp_path / "m", np.zeros(4), grid, unknown=np.zeros(4))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        save_ros_map(tmp_path / "m", np.full(4, -0.1), grid)
    with pytest.raises(ValueError, match="thresholds"):
        save_ros_map(tmp_path / "m", np.zeros(4), grid, thresholds="ros3")
    assert not list(tmp_path.iterdir())
    assert math.isclose(save_ros_map(tmp_path / "m", np.zeros(4), grid).settings.free_thresh, 0.196)


def test_raw_mode_and_yaw(tmp_path):
    text = GOOD.replace("[0.0, 0.0, 0.0]", "[0.0, 0.0, 0.5]") + "mode: raw\n"
    y = _write(tmp_path, text, b"P5\n2 2\n255\n" + bytes([0, 100, 101, 200]))
    with pytest.warns(UserWarning, match="yaw"):
        m = load_ros_map(y)
    assert m.settings.origin[2] == 0.5 and m.grid.origin == (0.0, 0.0)
    assert m.occupancy.tolist() == [-1, -1, 0, 100]  # Nav2: the grey itself, -1 outside 0..100
    with pytest.warns(UserWarning, match="yaw"):
        m1 = load_ros_map(y, flavor="ros1")
    assert m1.occupancy.tolist() == [101, -56, 0, 100]  # ROS 1: unsigned char stored as int8


@pytest.mark.parametrize(
    ("value", "tag"),
    [('!!python/object/apply:os.system ["true"]', "!!python/object/apply:os.system"), ("!!binary aGk=", "!!binary")],
)
def test_yaml_tags_other_than_yaml_types_are_refused_naming_the_file_and_line(tmp_path, value, tag):
    y = _write(tmp_path, GOOD + f"extra: {value}\n")
    with pytest.raises(RosMapError, match=f"line 7: tag '{re.escape(tag)}' is not allowed") as e:
        load_ros_map(y)
    assert str(y) in str(e.value)
    y = _write(tmp_path, GOOD.replace("image: map.pgm", "image: !local map.pgm"))
    with pytest.raises(RosMapError, match="line 1: tag '!local' is not allowed"):
        load_ros_map(y)


def test_yaml_parse_errors_name_the_file_and_line(tmp_path):
    y = _write(tmp_path, GOOD.replace("[0.0, 0.0, 0.0]", "[0.0, 0.0, 0.0"))
    with pytest.raises(RosMapError, match=r"malformed YAML: line 4: .*flow sequence on line 3") as e:
        load_ros_map(y)
    assert str(y) in str(e.value)
    deep = _write(tmp_path, GOOD + "extra: " + "[" * 5000 + "\n")  # the composer recurses per level
    with pytest.raises(RosMapError, match="malformed YAML"):
        load_ros_map(deep)
    with pytest.raises(RosMapError, match="line 7: character #x0000"):
        load_ros_map(_write(tmp_path, GOOD + "extra: a\0b\n"))


def test_yaml_scalars_are_read_from_their_text(tmp_path):
    """Quoted numbers are numbers and YAML 1.1 booleans are booleans (as map_server's yaml-cpp reads them);
    tabs after a key's colon or before a comment are separation, a tab that indents is not; a null mode is
    the default."""
    text = GOOD.replace("resolution: 0.1", 'resolution: "0.25"').replace("negate: 0", "negate:\tyes  \t# on")
    m = load_ros_map(_write(tmp_path, text + "mode: ~\nnote: 12\n"))
    assert m.grid.resolution == 0.25 and m.settings.negate and m.settings.mode == "trinary"
    assert m.settings.extra == {"note": "12"}
    with pytest.raises(RosMapError, match=r"malformed YAML: line 4: .*'\\t'"):
        load_ros_map(_write(tmp_path, GOOD.replace("origin: [0.0, 0.0, 0.0]", "origin:\n\t- 0\n\t- 0\n\t- 0")))


def test_written_yaml_reads_as_typed_yaml(tmp_path):
    """The YAML written is plain YAML of the types the module docstring lists, for any YAML reader."""
    from ruamel.yaml import YAML

    grid = Grid((2, 3), resolution=1e-5, origin=(-1.5, 1e20))
    files = save_ros_map(tmp_path / "lab map", np.full(6, 0.1), grid, negate=True)
    doc = YAML(typ="safe").load(files.yaml.read_text())
    assert doc == {
        "image": "lab map.pgm",
        "mode": "trinary",
        "resolution": 1e-5,
        "origin": [-1.5, 1e20, 0.0],
        "negate": 1,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    assert all(type(doc[k]) is float for k in ("resolution", "occupied_thresh", "free_thresh"))
