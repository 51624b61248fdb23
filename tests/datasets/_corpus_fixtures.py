"""Small synthetic files in the formats of the vector floor-plan corpora (houseexpo-full, r2v, schools), written
under a corpora folder as :func:`ogm_ppl.datasets.floorplans.floorplan_root` expects them."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

#: a house of two rooms, 4 m x 3 m outside, a 0.1 m wall at x = 2 with a 0.8 m gap (metres)
HOUSE = [
    [0.1, 0.1], [2.05, 0.1], [2.05, 1.0], [2.15, 1.0], [2.15, 0.1], [4.1, 0.1], [4.1, 3.1], [2.15, 3.1],
    [2.15, 1.8], [2.05, 1.8], [2.05, 3.1], [0.1, 3.1],
]  # fmt: skip
HOUSE_IDS = ("0a1b", "7f00", "c3d2")


def write_houseexpo(root: Path, lines: list[str] | None = None) -> Path:
    """``houseexpo-full/houseexpo_verts.jsonl.gz`` under ``root``: the given lines, else three houses (the ids of
    :data:`HOUSE_IDS`, each :data:`HOUSE` shifted)."""
    if lines is None:
        lines = [
            json.dumps({"id": i, "room_num": 2, "verts": [[x + k, y] for x, y in HOUSE]})
            for k, i in enumerate(HOUSE_IDS)
        ]
    path = root / "houseexpo-full" / "houseexpo_verts.jsonl.gz"
    path.parent.mkdir(parents=True, exist_ok=True)
    with gzip.open(path, "wt") as f:
        f.write("\n".join(lines) + "\n")
    return path


#: an apartment of two rooms, 400 x 300 px: outer walls, a wall at x = 200 with an opening of 30 px, an opening
#: of 60 px in the outer wall (a window) and two more openings of 30 px and 30 px lying on the outer wall too;
#: the 25th percentile of the openings is 30 px, so the scale is 0.75 / 30 = 0.025 m/px (10 m x 7.5 m)
R2V_LINES = [
    "0\t0\t400\t0\twall\t1\t1\t",
    "400\t0\t400\t300\twall\t1\t1\t",
    "400\t300\t0\t300\twall\t1\t1\t",
    "0\t300\t0\t0\twall\t1\t1\t",
    "200\t0\t200\t300\twall\t1\t1\t",
    "200\t120\t200\t150\tdoor\t1\t1\t",
    "60\t0\t120\t0\tdoor\t1\t1\t",
    "260\t300\t290\t300\tdoor\t1\t1\t",
    "400\t100\t400\t130\tdoor\t1\t1\t",
    "40\t40\t80\t60\tbedroom\t1\t1\t",
    "240\t40\t280\t60\tkitchen\t1\t1\t",
    "250\t200\t280\t230\ttoilet\t1\t1\t",
]
R2V_NAMES = (
    "00/aa/0000000000000000000000000001/0001",
    "00/aa/0000000000000000000000000002/0001",
    "00/bb/0000000000000000000000000003/0002",
    "00/bb/0000000000000000000000000004/0001",
)


def write_r2v(root: Path, plans: dict[str, list[str]] | None = None, lists: dict[str, list[str]] | None = None) -> Path:
    """``r2v-lifull/`` under ``root``: each plan's lines (default :data:`R2V_LINES` for every name of
    :data:`R2V_NAMES`) and the split lists (default: the first plan in train and test, the second in val, the
    third in train, the fourth in none)."""
    base = root / "r2v-lifull"
    plans = plans if plans is not None else {n: R2V_LINES for n in R2V_NAMES}
    for name, lines in plans.items():
        p = base / "floorplan_representation" / f"{name}.txt"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("\n".join(lines) + "\n")
    if lists is None:
        n = R2V_NAMES
        lists = {"train": [n[0], n[2]], "val": [n[1]], "test": [n[0]]}
    d = base / "splits_at_commit_621fe98"
    d.mkdir(parents=True, exist_ok=True)
    for split in ("train", "val", "test"):
        rows = [f"floorplan_image/{x}.jpg\tfloorplan_representation/{x}.txt" for x in lists.get(split, [])]
        (d / f"{split}.txt").write_text("".join(r + "\n" for r in rows))
    return base


def _space(sid: str, label: str, poly: list[tuple[int, int]], segments: list[tuple[str, str, tuple]]) -> str:
    pts = "".join(f'<point x="{x}" y="{y}" />' for x, y in poly)
    segs = "".join(
        f'<linesegment id="{i}"><point x="{a}" y="{b}" /><point x="{c}" y="{d}" /><class>{k}</class></linesegment>'
        for i, k, (a, b, c, d) in segments
    )
    return (
        f'<space id="{sid}"><labels><type>R</type><label>{label}</label></labels>'
        f"<bounding_polygon>{pts}</bounding_polygon><space_representation>{segs}</space_representation></space>"
    )


def school_xml(scale: str | None = "<value>30</value><um>pixel</um>", poly_b: list | None = None) -> str:
    """A floor of two rooms side by side, 300 x 200 px each (at 30 px = 90 cm: 9 m x 6 m), joined by a portal
    given as one point (300, 100) in both, and a third room below the first joined by a portal traced end to
    end (from (100, 200) to (130, 200))."""
    a = [(0, 0), (300, 0), (300, 200), (0, 200), (0, 0)]
    b = poly_b if poly_b is not None else [(300, 0), (600, 0), (600, 200), (300, 200), (300, 0)]
    c = [(0, 200), (300, 200), (300, 400), (0, 400), (0, 200)]
    space_a = _space(
        "A",
        "CLASSROOM",
        a,
        [
            ("a1", "WALL", (0, 0, 300, 0)),
            ("a2", "WALL", (300, 0, 300, 100)),
            ("p1", "PORTAL", (300, 100, 300, 100)),
            ("a3", "WALL", (300, 100, 300, 200)),
            ("a4", "WALL", (300, 200, 130, 200)),
            ("p2", "PORTAL", (130, 200, 130, 200)),
            ("a5", "WALL", (130, 200, 0, 200)),
            ("a6", "WALL", (0, 200, 0, 0)),
        ],
    )
    space_b = _space(
        "B",
        "CORRIDOR",
        b,
        [
            ("b1", "WALL", (300, 0, 600, 0)),
            ("b2", "WALL", (600, 0, 600, 200)),
            ("b3", "WALL", (600, 200, 300, 200)),
            ("b4", "WALL", (300, 200, 300, 100)),
            ("p1", "PORTAL", (300, 100, 300, 100)),
            ("b5", "WALL", (300, 100, 300, 0)),
        ],
    )
    space_c = _space(
        "C",
        "OFFICE",
        c,
        [
            ("c1", "WALL", (0, 200, 100, 200)),
            ("p2", "PORTAL", (100, 200, 100, 200)),
            ("c2", "WALL", (100, 200, 300, 200)),
            ("c3", "WALL", (300, 200, 300, 400)),
            ("c4", "WALL", (300, 400, 0, 400)),
            ("c5", "WALL", (0, 400, 0, 200)),
        ],
    )
    sc = "" if scale is None else (
        f"<scale><represented_distance>{scale}</represented_distance>"
        "<real_distance><value>90</value><um>cm</um></real_distance></scale>"
    )  # fmt: skip
    return f'<building id="x"><name>t</name>{sc}<floor><spaces>{space_a}{space_b}{space_c}</spaces></floor></building>'


def write_schools(root: Path, files: dict[str, str] | None = None) -> Path:
    """``schools-luperto/xml/<name>_updated.xml`` under ``root`` (default two floors of one school and another
    school, each :func:`school_xml`)."""
    d = root / "schools-luperto" / "xml"
    d.mkdir(parents=True, exist_ok=True)
    files = files if files is not None else {"Alpha1": school_xml(), "Alpha2": school_xml(), "beta": school_xml()}
    for name, text in files.items():
        (d / f"{name}_updated.xml").write_text(text)
    return d
