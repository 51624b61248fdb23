import gzip
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ogm_ppl.cli import build_parser, load_map, main
from ogm_ppl.datasets import load_dataset, read_carmen
from ogm_ppl.rosmap import load_ros_map

MAP_FILES = ("map.npz", "map.png", "ros/map.yaml", "ros/map.pgm", "ros/map.npz", "report.json", "report.md")
ROOM = (0.0, 4.0, 0.0, 3.0)  # xmin xmax ymin ymax of the tiny log's box room
POSES = [(1.0, 1.0, 0.0), (2.0, 1.5, 0.5), (1.5, 2.0, np.pi / 2), (3.0, 2.2, 2.5)]


def _box_ranges(x, y, th, n=181):
    ang = th + np.linspace(-np.pi / 2, np.pi / 2, n)
    dx, dy = np.cos(ang), np.sin(ang)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (ROOM[1] - x) / dx, np.where(dx < 0, (ROOM[0] - x) / dx, np.inf))
        ty = np.where(dy > 0, (ROOM[3] - y) / dy, np.where(dy < 0, (ROOM[2] - y) / dy, np.inf))
    return np.minimum(tx, ty)


def flaser_line(x, y, th, ts=1.0, ranges=None):
    r = _box_ranges(x, y, th) if ranges is None else ranges
    vals = " ".join(f"{v:.3f}" for v in r)
    return f"FLASER {len(r)} {vals} {x} {y} {th:.4f} {x} {y} {th:.4f} {ts} host {ts}\n"


def write_log(path, extra_lines=(), gz=False):
    text = "# a tiny CARMEN log: a 4 x 3 m box room\nPARAM robot_front_laser_max 20.0\n"
    text += "".join(flaser_line(*p, ts=i + 1.0) for i, p in enumerate(POSES))
    text += "".join(extra_lines)
    if gz:
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    return path


@pytest.fixture(scope="module")
def tiny_log(tmp_path_factory):
    return write_log(tmp_path_factory.mktemp("log") / "tiny.log")


@pytest.fixture(scope="module")
def sim_dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "sim.npz"
    argv = [
        "simulate",
        "--map",
        "generated",
        "office",
        "--size",
        "80",
        "--poses",
        "3",
        "--beams",
        "120",
        "--max-range-cells",
        "20",
        "--seed",
        "1",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    return out


def _check_outputs(out: Path):
    for name in MAP_FILES:
        assert (out / name).stat().st_size > 0, name
    assert not [p for p in out.rglob("*") if ".tmp" in p.name or p.name.startswith(".")]  # atomic writes
    m = load_map(out / "map.npz")
    ros = load_ros_map(out / "ros" / "map.yaml")
    assert ros.grid == m["grid"]
    assert ros.occupancy.size == m["grid"].num_cells
    p = m["probabilities"]
    assert p.shape == m["grid"].shape and np.all((p >= 0) & (p <= 1))
    assert m["observed"].any() and not m["observed"].all()
    report = json.loads((out / "report.json").read_text())
    for k in ("read", "ray_cast", "map", "write"):
        assert k in report["times_s"]
    from PIL import Image

    with Image.open(out / "map.png") as im:
        assert im.size == (m["grid"].cols, m["grid"].rows)
    return m, report


def test_run_writes_figures_and_report(tmp_path, capsys):
    from ogm_ppl.experiment.headline import INTEL_LOG, find_shared_file

    log = find_shared_file(INTEL_LOG)
    if log is None:
        pytest.skip("the shared Intel Lab log is not here")
    assert main(["run", "--out", str(tmp_path), "--quick", "--scheduler", "serial", "--log", str(log)]) == 0
    for name in ("simple2d_maps.png", "toy1d_marginals.png", "intel_maps.png", "report.md", "report.json"):
        assert (tmp_path / name).stat().st_size > 0
    assert not list(tmp_path.glob("*.tmp*"))  # atomic writes leave nothing behind
    report = json.loads((tmp_path / "report.json").read_text())
    intel = {r["algorithm"]: r for r in report["intel"]["pooled"]}
    assert set(intel) == {"ogm", "p21", "learned-L9", "guide"}
    for r in intel.values():  # the real-data part: scores that mean something, on both masks
        assert 0.5 < r["mask"]["best_f1"] <= 1 and 0.7 < r["mask"]["auc"] <= 1
        assert 0.3 < r["touched"]["best_f1"] <= 1
    assert "Real data: the Intel Lab log" in (tmp_path / "report.md").read_text()
    maps = report["simple2d"]["maps"]
    assert len(maps) == 7
    for r in maps.values():
        assert 0 < r["best_f1"] <= 1 and 0.5 < r["roc_auc"] <= 1
    # keeping cell correlations (patch map, Gibbs) beats every independent-cell map on this example
    independent = [r["roc_auc"] for k, r in maps.items() if "Gibbs" not in k and "patch" not in k]
    correlated = [r["roc_auc"] for k, r in maps.items() if "Gibbs" in k or "patch" in k]
    assert min(correlated) > max(independent)
    assert "| map | best F1" in capsys.readouterr().out


def test_run_without_the_log_runs_the_simulated_part(tmp_path, monkeypatch, capsys):
    import ogm_ppl.experiment.headline as headline

    monkeypatch.setattr(headline, "find_shared_file", lambda rel: None)
    simulated = {"markdown": ["simulated part"]}
    monkeypatch.setattr("ogm_ppl.experiment.headline.run_simple2d", lambda out, seed: simulated)
    assert main(["run", "--out", str(tmp_path)]) == 0
    text = (tmp_path / "report.md").read_text()
    assert "Real data: skipped" in text and "pass --log PATH" in text and "simulated part" in text
    assert "running the simulated part only" in capsys.readouterr().err


def test_run_with_a_missing_log_is_an_error(tmp_path, capsys):
    assert main(["run", "--out", str(tmp_path), "--log", str(tmp_path / "nope.log")]) == 2
    assert "nope.log" in capsys.readouterr().err


def test_version(capsys):
    from importlib.metadata import version

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"ogm-ppl {version('ogm_ppl')}"


def test_every_option_has_help():
    """Every option and positional of every subcommand (and of the sub-subcommands, as ``fit-prior``'s kinds) has
    help text, and the subcommands are those of ``COMMANDS``, each a module with ``add_parser`` and ``run``."""
    import argparse
    import importlib

    from ogm_ppl.cli import COMMANDS

    def walk(name, p):
        for a in p._actions:
            assert a.help, (name, a.option_strings or a.dest)
            if isinstance(a, argparse._SubParsersAction):
                for sub_name, q in a.choices.items():
                    yield from walk(f"{name} {sub_name}", q)
        yield name

    names = list(walk("ogm-ppl", build_parser()))
    top = {n.split()[1] for n in names if len(n.split()) == 2}
    assert top == set(COMMANDS) >= {"map", "methods", "simulate", "convert", "info", "experiment", "run"}
    assert {"calibrate", "train-guide", "fit-prior"} <= top
    assert {"ogm-ppl fit-prior tables", "ogm-ppl fit-prior field", "ogm-ppl fit-prior deltas"} <= set(names)
    for module in COMMANDS.values():
        mod = importlib.import_module(f"ogm_ppl.cli.{module}")
        assert callable(mod.add_parser) and callable(mod.run), module


def test_map_carmen_log(tmp_path, tiny_log, capsys):
    out = tmp_path / "out"
    assert main(["map", str(tiny_log), "--resolution", "0.1", "--out", str(out)]) == 0
    m, report = _check_outputs(out)
    assert report["counts"]["scans"] == len(POSES) and report["counts"]["beams"] == 181 * len(POSES)
    assert report["input"]["kind"] == "carmen" and report["method"]["delta"] == "haehnel"
    g = m["grid"]  # the room plus the 1 m margin
    assert g.resolution == 0.1 and g.origin == pytest.approx((-1.0, -1.0), abs=0.01)
    # the walls of the room are occupied, its inside free
    p = m["probabilities"]
    wall = g.world_to_cell([[4.02, 1.5], [2.0, 3.02]])
    inside = g.world_to_cell([[2.0, 1.0], [3.0, 2.5]])
    assert np.all(p[wall[:, 0], wall[:, 1]] > 0.6) and np.all(p[inside[:, 0], inside[:, 1]] < 0.3)
    assert "ogm-ppl map:" in capsys.readouterr().out


def test_map_gzip_log_and_lenient(tmp_path):
    log = write_log(tmp_path / "bad.log.gz", ["FLASER 3 1.0 oops 2.0 0 0 0 0 0 0 9.0 host 9.0\n"], gz=True)
    assert main(["map", str(log), "--out", str(tmp_path / "strict")]) == 2
    assert not (tmp_path / "strict").exists()  # an error leaves no empty directory behind
    assert main(["map", str(log), "--lenient", "--method", "p21", "--out", str(tmp_path / "o")]) == 0
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert report["counts"]["bad_lines"] == 1 and report["bad_lines"][0]["line"] == 7
    assert "line 7" in (tmp_path / "o" / "report.md").read_text()


@pytest.mark.parametrize(
    "method,extra",
    [
        ("ogm", []),
        ("p21", []),
        ("elfes", []),
        ("ogm", ["--delta", "moravec_thesis"]),
        ("gibbs", ["--sweeps", "5"]),
        ("gibbs", ["--sweeps", "3", "--patch", "2x2", "--warmup", "1", "--seed", "3"]),
        ("patch", ["--patch", "3", "--lambda", "0.5"]),
        ("gibbs", ["--sweeps", "5", "--prior", "mrf:houseexpo"]),
        ("gibbs", ["--sweeps", "3", "--prior", "border1:houseexpo"]),
    ],
)
def test_map_simulated_dataset_each_method(tmp_path, sim_dataset, method, extra):
    out = tmp_path / method
    assert main(["map", str(sim_dataset), "--method", method, *extra, "--out", str(out)]) == 0
    m, report = _check_outputs(out)
    ds = load_dataset(sim_dataset)
    assert m["grid"] == ds.grid  # a dataset's own grid by default
    assert report["method"]["name"] == method
    sc = report["scores_vs_truth"]
    assert sc is not None and sc["roc_auc"] > 0.6
    if method == "gibbs":
        assert report["method"]["kernel"] == ("PatchGibbs" if "--patch" in extra else "CellGibbs")
        assert report["times_s"]["ray_cast"] is not None


def test_map_subsampling_and_explicit_grid(tmp_path, sim_dataset):
    out = tmp_path / "o"
    argv = [
        "map",
        str(sim_dataset),
        "--beam-step",
        "2",
        "--pose-step",
        "2",
        "--size",
        "70",
        "65",
        "--origin",
        "-0.1",
        "-0.2",
        "--resolution",
        "0.05",
        "--thresholds",
        "nav2",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    m, report = _check_outputs(out)
    assert m["grid"].shape == (65, 70) and m["grid"].origin == (-0.1, -0.2)
    assert report["counts"]["scans"] == 2 and report["counts"]["beams"] == 2 * 60
    assert load_ros_map(out / "ros" / "map.yaml").settings.free_thresh == 0.25


def test_simulate_then_map_reproducible(tmp_path, sim_dataset):
    again = tmp_path / "again.npz"
    argv = [
        "simulate",
        "--map",
        "office",
        "--size",
        "80",
        "--poses",
        "3",
        "--beams",
        "120",
        "--max-range-cells",
        "20",
        "--seed",
        "1",
        "--out",
        str(again),
    ]
    assert main(argv) == 0
    a, b = load_dataset(sim_dataset), load_dataset(again)
    assert np.array_equal(a.scans.ranges, b.scans.ranges) and np.array_equal(a.truth, b.truth)
    assert a.truth.shape == (80, 80) and a.scans.num_scans == 3 and a.scans.beams_per_scan == 120
    assert a.settings["sigma_cells"] == 3.0 and a.settings["kind"] == "office"


def test_simulate_png_floor_plan(tmp_path):
    from PIL import Image

    img = np.full((70, 90), 255, np.uint8)
    img[35, 10:80] = 0  # one dark wall across the middle
    Image.fromarray(img).save(tmp_path / "plan.png")
    out = tmp_path / "plan.npz"
    assert (
        main(
            [
                "simulate",
                "--map",
                str(tmp_path / "plan.png"),
                "--poses",
                "2",
                "--beams",
                "60",
                "--max-range-cells",
                "20",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    d = load_dataset(out)
    assert d.truth.shape == (70, 90) and d.truth[70 - 1 - 35, 40] and not d.truth[10, 40]


def test_convert_round_trip(tmp_path, tiny_log):
    out = tmp_path / "d.npz"
    assert main(["convert", str(tiny_log), "--out", str(out), "--beam-step", "2"]) == 0
    d = load_dataset(out)
    log = read_carmen(tiny_log, beam_step=2)
    for k in ("poses", "angles", "ranges", "valid"):
        assert np.array_equal(getattr(d.scans, k), getattr(log.scans, k)), k
    assert d.scans.max_range == log.scans.max_range and d.provenance["source"] == str(tiny_log)
    # mapping the dataset gives the map of the log
    assert main(["map", str(out), "--out", str(tmp_path / "a")]) == 0
    assert main(["map", str(tiny_log), "--beam-step", "2", "--out", str(tmp_path / "b")]) == 0
    a, b = load_map(tmp_path / "a" / "map.npz"), load_map(tmp_path / "b" / "map.npz")
    assert a["grid"] == b["grid"] and np.array_equal(a["probabilities"], b["probabilities"])


# ------------------------------------------------------------------------------- malformed input
def _bad_files(d: Path, tiny_log: Path, sim: Path) -> dict[str, Path]:
    files = {}
    files["badnum"] = write_log(d / "badnum.log", ["FLASER 3 1.0 x 2.0 0 0 0 0 0 0 9.0 host 9.0\n"])
    files["short"] = write_log(d / "short.log", ["FLASER 3 1.0 2.0 3.0 0 0\n"])
    files["text"] = d / "text.txt"
    files["text"].write_text("hello world\nthis is not a log\n")
    files["binary"] = d / "binary.log"
    files["binary"].write_bytes(bytes(range(256)) + b"\n")
    files["empty"] = d / "empty.log"
    files["empty"].write_bytes(b"")
    full = gzip.compress(tiny_log.read_bytes())
    files["truncgz"] = d / "trunc.log.gz"
    files["truncgz"].write_bytes(full[: len(full) // 2])
    files["foreign"] = d / "foreign.npz"
    np.savez(files["foreign"], a=np.arange(3))
    files["truncnpz"] = d / "trunc.npz"
    files["truncnpz"].write_bytes(sim.read_bytes()[:200])
    with np.load(sim, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["format_version"] = np.int64(99)
    files["version"] = d / "version.npz"
    np.savez(files["version"], **arrays)
    files["regular"] = d / "regular_file"
    files["regular"].write_text("x")
    files["dir"] = d / "a_directory"
    files["dir"].mkdir()
    return files


# (argv with {placeholders}, substring of the message)
MALFORMED = [
    ("map {d}/missing.log --out {d}/o", "no such file"),
    ("map {dir} --out {d}/o", "is a directory"),
    ("map {badnum} --out {d}/o", "line 7, field 'range[1]'"),
    ("map {short} --out {d}/o", "line 7"),
    ("map {text} --out {d}/o", "no readable laser scans"),
    ("map {binary} --out {d}/o", "line 1, field 'message type'"),
    ("map {empty} --out {d}/o", "no readable laser scans"),
    ("map {truncgz} --out {d}/o", "corrupt or truncated gzip"),
    ("map {foreign} --out {d}/o", "not an ogm_ppl dataset"),
    ("map {truncnpz} --out {d}/o", "truncated or corrupt"),
    ("map {version} --out {d}/o", "format version 99"),
    ("map {log} --out {regular}/sub", "cannot write there"),
    ("map {log} --out {regular}", "exists and is not a directory"),
    ("map {log} --out {d}/o --seed -1", "argument --seed: must be >= 0, got -1"),
    ("map {log} --out {d}/o --resolution 0", "argument --resolution: must be > 0"),
    ("map {log} --out {d}/o --resolution -0.05", "argument --resolution: must be > 0"),
    ("map {log} --out {d}/o --resolution nan", "must be finite"),
    ("map {log} --out {d}/o --resolution abc", "expected a number, got 'abc'"),
    ("map {sim} --out {d}/o --method gibbs --sweeps 0", "argument --sweeps: must be >= 1"),
    ("map {log} --out {d}/o --method foo", "unknown method 'foo'"),
    ("map {sim} --out {d}/o --method gibbs --prior mrf:nowhere", "no shipped tables for corpus 'nowhere'"),
    ("map {sim} --out {d}/o --method gibbs --prior crf:houseexpo", "unknown prior kind 'crf'"),
    ("map {sim} --out {d}/o --method gibbs --prior crf:houseexpo", "name the module in $OGM_PPL_METHODS"),
    ("map {log} --out {d}/o --delta nope", "unknown Delta name 'nope'"),
    ("map {log} --out {d}/o --method gibbs --delta p21", "--delta sets the parameter 'delta' of ogm"),
    ("map {log} --out {d}/o --warmup 2", "--warmup sets the parameter 'burn_in' of gibbs"),
    ("map {log} --out {d}/o --param sweeps=3", "--param sweeps: unknown key (known here: clamp, delta"),
    ("map {sim} --out {d}/o --method gibbs --param scan=diagonal", "--param scan: must be one of"),
    ("map {sim} --out {d}/o --method gibbs --param sweeps", "expected KEY=VALUE"),
    ("map {sim} --out {d}/o --method gibbs --sweeps 3 --param sweeps=4", "--param sweeps repeats"),
    ("map {sim} --out {d}/o --method gibbs --prior mrf:houseexpo --lambda 0.3", "--lambda: applies to"),
    ("methods nope", "unknown method 'nope'"),
    ("map {sim} --out {d}/o --method patch --patch 2y3", "argument --patch"),
    ("map {log} --out {d}/o --size 10000 10000", "more than the limit of 50,000,000"),
    ("map {log} --out {d}/o --resolution 0.0005", "more than the limit of 50,000,000"),
    ("map {log} --out {d}/o --size 10 10 --origin 100 100", "lies outside the grid"),
    ("map {log} --out {d}/o --size 5 5 --auto-extent", "not allowed with argument"),
    ("map {log} --out {d}/o --pose-fraction 1.5", "must be <= 1"),
    ("map {log} --out {d}/o --pose-step 2 --pose-fraction 0.5", "not allowed with argument"),
    ("map {log} --out {d}/o --no-return maybe", "invalid choice: 'maybe'"),
    ("map {sim} --out {d}/o --lenient", "--lenient applies to CARMEN logs"),
    ("map {log}", "the following arguments are required: --out"),
    ("frobnicate", "invalid choice: 'frobnicate'"),
    ("", "the following arguments are required: COMMAND"),
    ("convert {log} --out {dir}", "is a directory"),
    ("convert {badnum} --out {d}/c.npz", "line 7"),
    ("simulate --map generated castle --out {d}/s.npz", "argument --map"),
    ("simulate --map office --size 10 --out {d}/s.npz", "argument --size: must be >= 60"),
    ("simulate --map {text} --out {d}/s.npz", "not a readable image"),
    ("simulate --map office --size 60 --sigma -1 --out {d}/s.npz", "argument --sigma"),
    ("run --out {regular}", "exists and is not a directory"),
]


def test_malformed_inputs_one_line_exit_2(tmp_path, tiny_log, sim_dataset, capsys):
    files = _bad_files(tmp_path, tiny_log, sim_dataset)
    names = {k: str(v) for k, v in files.items()}
    names |= {"d": str(tmp_path), "log": str(tiny_log), "sim": str(sim_dataset)}
    seen = []
    for argv, expected in MALFORMED:
        args = [a.format(**names) for a in argv.split()]
        rc = main(args)
        cap = capsys.readouterr()
        lines = cap.err.strip("\n").split("\n")
        seen.append((argv, cap.err.strip()))
        assert rc == 2, (argv, cap.err)
        assert len(lines) == 1 and lines[0].startswith("ogm-ppl: error: "), (argv, cap.err)
        assert "Traceback" not in cap.err + cap.out, argv
        assert expected in lines[0], (argv, lines[0])
    assert len(seen) >= 20
    assert not (tmp_path / "o").exists()  # failed maps leave no output directory


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root can write to read-only directories")
def test_read_only_out_dir(tmp_path, tiny_log, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert main(["map", str(tiny_log), "--out", str(ro / "o")]) == 2
        assert "cannot write there" in capsys.readouterr().err
    finally:
        ro.chmod(0o755)


def test_console_entry_prints_no_traceback(tmp_path):
    exe = Path(sys.executable).with_name("ogm-ppl")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "ogm_ppl"]
    bad = tmp_path / "bad.log"
    bad.write_text("FLASER 2 1.0 nope 0 0 0 0 0 0 1.0 host 1.0\n")
    r = subprocess.run(
        [*cmd, "map", str(bad), "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1
    assert r.stderr.startswith("ogm-ppl: error: ") and "line 1, field 'range[1]'" in r.stderr


def test_experiment_subcommand(tmp_path, capsys):
    spec = Path(__file__).resolve().parent.parent / "experiments" / "specs" / "smoke.toml"
    out = tmp_path / "smoke"
    assert main(["experiment", str(spec), "--scheduler", "serial", "--quiet", "--out", str(out)]) == 0
    got = capsys.readouterr()
    assert (out / "metrics.md").exists() and "tasks run" in got.out and got.err == ""  # --quiet: nothing
    # without a terminal (captured stderr) and without --quiet: plain progress lines, first and last
    assert main(["experiment", str(spec), "--scheduler", "serial", "--no-resume", "--out", str(out)]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].startswith("tasks: 0/") and lines[-1].endswith("done") and "\r" not in "".join(lines)
    # a subset of the algorithms, then an unknown one (refused by name)
    sub = tmp_path / "sub"
    from ogm_ppl.experiment import load_spec

    first = load_spec(spec).algorithms[0].name
    assert (
        main(["experiment", str(spec), "--scheduler", "serial", "--quiet", "--out", str(sub), "--algorithms", first])
        == 0
    )
    ran = json.loads((sub / "spec.json").read_text())["algorithms"]
    assert [a["name"] for a in ran] == [first]
    capsys.readouterr()
    assert main(["experiment", str(spec), "--out", str(sub), "--algorithms", "nope"]) == 2
    assert "no algorithm 'nope'" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("[experiment]\nname = 3\n")
    assert main(["experiment", str(bad), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ogm-ppl: error: ") and "bad.toml" in err and "Traceback" not in err


# ------------------------------------------------------------------------------------- ROS bags
@pytest.fixture(scope="module")
def tiny_bags(tiny_log, tmp_path_factory):
    """The tiny log as a ROS 1 bag (pose topic), an MCAP bag (pose topic) and a sqlite3 bag (/tf with a
    laser mounting): rosbags' own writers via ogm_ppl.datasets.rosbag.write_bag."""
    from ogm_ppl.datasets.rosbag import write_bag

    tmp = tmp_path_factory.mktemp("bags")
    log = read_carmen(tiny_log, max_usable_range=20.0)
    s, t = log.scans, log.timestamps
    return {
        "ros1": write_bag(tmp / "tiny.bag", s, t),
        "mcap": write_bag(tmp / "tiny_mcap", s, t, storage="mcap"),
        "tf": write_bag(tmp / "tiny_tf", s, t, storage="sqlite3", tf=True, laser_offset=(0.1, 0.02, 0.05)),
    }


def test_map_of_a_bag_equals_the_map_of_the_log(tmp_path, tiny_log, tiny_bags):
    # one grid for all (the automatic extent follows the hits, and the yaw through a quaternion may move
    # one by an ulp)
    common = ["--resolution", "0.1", "--size", "62", "52", "--origin", "-1.1", "-1.1", "--max-usable-range", "20"]
    assert main(["map", str(tiny_log), *common, "--out", str(tmp_path / "log")]) == 0
    ref = load_map(tmp_path / "log" / "map.npz")
    for name, src in (
        ("ros1", ["--pose-topic", "/odom"]),
        ("mcap", ["--scan-topic", "/scan", "--pose-topic", "/odom"]),
        ("tf", ["--tf"]),
    ):
        out = tmp_path / name
        assert main(["map", str(tiny_bags[name]), *src, *common, "--out", str(out)]) == 0, name
        m, report = _check_outputs(out)
        assert m["grid"] == ref["grid"], name
        assert np.array_equal(m["probabilities"], ref["probabilities"]), name
        assert report["input"]["kind"] == "bag" and report["counts"]["no_pose"] == 0
        assert report["bag"]["poses"] == ("tf" if name == "tf" else "/odom")
        assert "bag (" in (out / "report.md").read_text()


def test_convert_a_bag(tmp_path, tiny_log, tiny_bags, capsys):
    out = tmp_path / "b.npz"
    assert (
        main(
            ["convert", str(tiny_bags["mcap"]), "--pose-topic", "/odom", "--max-usable-range", "20", "--out", str(out)]
        )
        == 0
    )
    assert "0 bad messages skipped" in capsys.readouterr().out
    ds, ref = load_dataset(out), read_carmen(tiny_log, max_usable_range=20.0).scans
    assert np.array_equal(ds.scans.ranges, ref.ranges) and np.array_equal(ds.scans.valid, ref.valid)
    np.testing.assert_allclose(ds.scans.poses, ref.poses, rtol=0, atol=1e-12)
    assert ds.provenance["reader"] == "ogm_ppl.datasets.read_bag"


def test_info_of_a_log_a_bag_and_a_dataset(tmp_path, tiny_log, tiny_bags, capsys):
    def info(*argv):
        assert main(["info", *map(str, argv), "--json"]) == 0
        return json.loads(capsys.readouterr().out)

    log = info(tiny_log, "--max-usable-range", "20")
    assert (log["kind"], log["scans"], log["beams_per_scan"]) == ("carmen", len(POSES), 181)
    assert log["angular_increment_deg"] == [1.0] and log["field_of_view_deg"] == 180.0
    assert log["first_beam_deg"] == -90.0 and log["max_range_m"] == 20.0
    assert log["duration_s"] == pytest.approx(len(POSES) - 1.0) and log["scan_rate_hz"] == pytest.approx(1.0)
    x, y = log["extent_m"]["x"], log["extent_m"]["y"]
    assert x[0] == pytest.approx(ROOM[0], abs=0.01) and y[1] == pytest.approx(ROOM[3], abs=0.01)
    bag = info(tiny_bags["tf"], "--max-usable-range", "20")  # the only pose source, /tf, found by itself
    assert bag["kind"] == "bag" and bag["storage"] == "sqlite3" and bag["poses"] == "tf"
    for k in ("scans", "beams_per_scan", "angular_increment_deg", "field_of_view_deg", "max_range_m"):
        assert bag[k] == log[k], k
    assert bag["pose_rate_hz"] == pytest.approx(1.0) and bag["message_range_max_m"] == [20.0]
    out = tmp_path / "d.npz"
    assert main(["convert", str(tiny_log), "--out", str(out)]) == 0
    capsys.readouterr()
    ds = info(out)
    assert ds["kind"] == "dataset" and ds["beams_per_scan"] == 181 and ds["duration_s"] is None
    assert main(["info", str(tiny_bags["ros1"])]) == 0
    text = capsys.readouterr().out
    assert "angular_increment_deg: 1\n" in text and "/scan  sensor_msgs/msg/LaserScan  4 messages" in text


def test_bag_errors_one_line(tmp_path, tiny_log, tiny_bags, capsys):
    cases = [
        (["map", tiny_bags["ros1"]], "give --pose-topic P (pose topics in the bag: /odom) or --tf"),
        (["map", tiny_bags["ros1"], "--pose-topic", "/pose"], "no pose topic '/pose' in the bag"),
        (["map", tiny_bags["ros1"], "--scan-topic", "/odom", "--pose-topic", "/odom"], "holds nav_msgs/msg/Odometry"),
        (["map", tiny_bags["tf"], "--tf", "--laser-offset", "0", "0", "0"], "--laser-offset applies to --pose-topic"),
        (["map", tiny_bags["tf"], "--tf", "--map-frame", "world"], "no transform chain from 'world'"),
        (["map", tiny_log, "--tf"], "--tf applies to ROS bags"),
        (["map", tiny_bags["ros1"], "--pose-topic", "/odom", "--tf"], "not allowed with argument"),
        (["info", tiny_log, "--scan-topic", "/scan"], "--scan-topic applies to ROS bags"),
    ]
    for argv, expected in cases:
        rc = main([*map(str, argv), "--out", str(tmp_path / "o")] if argv[0] == "map" else list(map(str, argv)))
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and err.startswith("ogm-ppl: error: "), (argv, err)
        assert expected in err, (argv, err)
    assert not (tmp_path / "o").exists()


def test_map_a_cut_ros1_bag_with_lenient(tmp_path, tiny_bags, capsys):
    cut = tmp_path / "cut.bag.active"
    data = tiny_bags["ros1"].read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.8)])
    assert main(["map", str(cut), "--pose-topic", "/odom", "--out", str(tmp_path / "o")]) == 2
    assert "--lenient reads it record by record" in capsys.readouterr().err
    assert main(["map", str(cut), "--pose-topic", "/odom", "--lenient", "--out", str(tmp_path / "o")]) == 0
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert 1 <= report["counts"]["scans"] < len(POSES) and report["counts"]["bad_messages"] == 1
    assert report["bad_messages"][0]["reason"].startswith("no usable index, read record by record")
    assert "## Skipped messages (--lenient)" in (tmp_path / "o" / "report.md").read_text()


def test_map_output_folder_is_all_old_or_all_new(tmp_path, tiny_log, monkeypatch):
    """An interruption while ``ogm-ppl map`` writes (here: in the ROS map) leaves the previous run's
    outputs, all of them, untouched; the folder never mixes two runs."""
    import ogm_ppl.rosmap

    out = tmp_path / "out"
    assert main(["map", str(tiny_log), "--resolution", "0.1", "--out", str(out)]) == 0
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(ogm_ppl.rosmap, "save_ros_map", interrupted)
    assert main(["map", str(tiny_log), "--resolution", "0.2", "--out", str(out)]) != 0
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".out")) == []


def test_an_interrupted_gibbs_map_resumes_from_its_checkpoint_bit_for_bit(sim_dataset, tmp_path, monkeypatch, capsys):
    """Ctrl-C (the sampler's stop flag, here after 4 sweeps) keeps the chain's checkpoint in DIR/.checkpoints and
    says so; the same command resumes it to the very map of an uninterrupted run and removes the checkpoints;
    another seed is another chain and starts afresh."""
    import ogm_ppl.inference.mcmc as mcmc

    argv = ["map", str(sim_dataset), "--method", "gibbs", "--sweeps", "20", "--warmup", "2"]
    argv += ["--param", "checkpoint_every=3", "--param", "chains=2"]
    assert main([*argv, "--out", str(tmp_path / "full")]) == 0
    full = load_map(tmp_path / "full" / "map.npz")
    real = mcmc.run_gibbs
    calls = []

    def interrupted(*a, **kw):  # the second chain (seed + 1) stops as Ctrl-C stops it, 4 sweeps in
        calls.append(kw["seed"])
        if kw["seed"] == calls[0] + 1:
            kw["stop_after"] = 4
        return real(*a, **kw)

    out = tmp_path / "o"
    monkeypatch.setattr(mcmc, "run_gibbs", interrupted)
    capsys.readouterr()
    assert main([*argv, "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert "interrupted; checkpoints kept in" in err and "the same command resumes" in err
    kept = sorted(p.relative_to(out).parts[-2] for p in out.glob(".checkpoints/*/chain-*/gibbs.npz"))
    assert kept == ["chain-0", "chain-1"] and not (out / "map.npz").exists()
    monkeypatch.setattr(mcmc, "run_gibbs", real)
    assert main([*argv, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.count("resumes from its checkpoint") == 2
    m = load_map(out / "map.npz")
    np.testing.assert_array_equal(m["probabilities"], full["probabilities"])
    assert m["settings"]["method_details"]["resumed_from_sweep"] == 4
    assert not (out / ".checkpoints").exists()
    _check_outputs(out)
    # another seed: other chains, nothing to resume
    monkeypatch.setattr(mcmc, "run_gibbs", interrupted)
    calls.clear()
    assert main([*argv, "--out", str(out), "--seed", "5"]) == 130
    monkeypatch.setattr(mcmc, "run_gibbs", real)
    capsys.readouterr()
    assert main([*argv, "--out", str(out), "--seed", "6"]) == 0
    err = capsys.readouterr().err
    assert "resumes from its checkpoint" not in err
    # the interrupted seed-5 chains stay, and a note says so; rerunning that command resumes and spends them
    assert len(list(out.glob(".checkpoints/*"))) == 1
    assert f"{out / '.checkpoints'} keeps the checkpoints of 1 other interrupted run(s)" in err
    assert main([*argv, "--out", str(out), "--seed", "5"]) == 0
    assert capsys.readouterr().err.count("resumes from its checkpoint") == 2
    assert not (out / ".checkpoints").exists()


def test_a_module_in_ogm_ppl_methods_that_cannot_be_imported_is_one_line_naming_it(monkeypatch, capsys):
    """A typo in $OGM_PPL_METHODS: one error line naming the variable, the module and the import's error (not
    a traceback), and the registry is not left half-filled: the next call, the variable mended, finds all."""
    from ogm_ppl import extensions
    from ogm_ppl.methods import registry

    monkeypatch.setattr(registry, "_discovered", False)
    monkeypatch.setattr(extensions, "_loaded", False)
    monkeypatch.setenv("OGM_PPL_METHODS", "no_such_module_xyz")
    capsys.readouterr()
    assert main(["methods"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "$OGM_PPL_METHODS names the module 'no_such_module_xyz'" in err[0]
    assert "ModuleNotFoundError" in err[0] and not registry._discovered
    monkeypatch.delenv("OGM_PPL_METHODS")
    assert "gibbs" in registry.method_names() and registry._discovered
    assert main(["map", "x.log", "--out", "o", "--method", "nonexistent"]) == 2
    assert "name the module in $OGM_PPL_METHODS" in capsys.readouterr().err


def _log_of(path, poses):
    path.write_text(
        "# part of the tiny log\nPARAM robot_front_laser_max 20.0\n"
        + "".join(flaser_line(*POSES[i], ts=i + 1.0) for i in poses)
    )
    return path


REGION = ["--size", "36", "60", "--origin", "0", "0"]  # x < 1.8 m: the poses 0 and 2 of the tiny log


@pytest.mark.parametrize(
    ("flags", "grid", "kept", "steps"),
    [
        (["--scans", "1:3"], [], [1, 2], ["4 read", "--scans 1:3: 2"]),
        # the stretch is cut first, then thinned
        (["--scans", "1:", "--pose-step", "2"], [], [1, 3], ["4 read", "--scans 1:: 3", "--pose-step 2: 2"]),
        (["--scans", ":2"], [], [0, 1], ["4 read", "--scans :2: 2"]),
        (["--crop"], REGION, [0, 2], ["4 read", "--crop: 2"]),
        (["--crop", "--scans", "1:"], REGION, [2], ["4 read", "--scans 1:: 3", "--crop: 1"]),
        (["--crop", "--pose-step", "3"], REGION, [0], ["2 read", "--crop: 1"]),  # the reader thinned them
    ],
)
def test_map_of_a_stretch_or_a_region_is_the_map_of_those_scans_alone(tmp_path, tiny_log, flags, grid, kept, steps):
    """``--scans A:B`` and ``--crop`` give the map of a log holding only the scans they keep, and the report
    says how many of the scans read were kept. (The sensor's range is fixed: a log without one gets the largest
    reading of all its scans, which a selection keeps.)"""
    part = _log_of(tmp_path / "part.log", kept)
    grid = [*grid, "--max-usable-range", "5"]
    assert main(["map", str(tiny_log), "--out", str(tmp_path / "a"), *flags, *grid]) == 0
    assert main(["map", str(part), "--out", str(tmp_path / "b"), *grid]) == 0
    a, b = load_map(tmp_path / "a" / "map.npz"), load_map(tmp_path / "b" / "map.npz")
    assert a["grid"] == b["grid"]
    np.testing.assert_array_equal(a["probabilities"], b["probabilities"])
    counts = json.loads((tmp_path / "a" / "report.json").read_text())["counts"]
    assert (counts["scans"], counts["selection"]) == (len(kept), steps)
    report = (tmp_path / "a" / "report.md").read_text()
    assert f"- scans: {len(kept)} ({'; '.join(steps)}); beams" in report
    assert "below min range 0 (over all the scans read); bad lines" in report


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--crop"], "--crop needs the grid's --size W H"),
        (["--method", "gibbs", "--online", "--threads", "1"], "--online sweeps around each new scan serially"),
        (["--scans", "7:9"], "--scans 7:9: "),
        (["--scans", "3:1"], "holds no scan (B must exceed A)"),
        (["--scans", "12"], "expected A:B (scan indices"),
        (["--scans=-1:2"], "scan indices must be >= 0"),
        (["--size", "10", "10", "--origin", "10", "10", "--crop"], "--crop: no pose of the 4 scans lies on the grid"),
        (REGION, "are outside; --crop maps the part the grid covers"),
    ],
)
def test_a_stretch_or_region_holding_no_scan_is_refused(tmp_path, tiny_log, capsys, flags, message):
    capsys.readouterr()
    assert main(["map", str(tiny_log), "--out", str(tmp_path / "a"), *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_python_m_cli_runs_the_command(tmp_path):
    """``python -m ogm_ppl.cli`` is the command, as ``python -m ogm_ppl`` is (it did nothing and exited 0)."""
    r = subprocess.run([sys.executable, "-m", "ogm_ppl.cli", "methods"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "gibbs" in r.stdout
    r = subprocess.run([sys.executable, "-m", "ogm_ppl.cli", "no_such_command"], capture_output=True, text=True)
    assert r.returncode == 2 and "invalid choice" in r.stderr


def test_unobserved_cells_are_unknown_in_the_image_and_ros_map_unless_predicted(sim_dataset, tmp_path):
    """``--unobserved predict`` draws and thresholds the cells no ray reached from their probability (what a
    correlated prior predicts there); by default they are unknown, whatever the method says of them."""
    from PIL import Image

    argv = ["map", str(sim_dataset), "--method", "gibbs", "--prior", "border1_bo:houseexpo", "--sweeps", "20"]
    assert main([*argv, "--out", str(tmp_path / "u")]) == 0
    assert main([*argv, "--out", str(tmp_path / "p"), "--unobserved", "predict"]) == 0
    m = load_map(tmp_path / "u" / "map.npz")
    np.testing.assert_array_equal(m["probabilities"], load_map(tmp_path / "p" / "map.npz")["probabilities"])
    hidden = ~m["observed"].ravel()
    p = m["probabilities"].ravel()
    decided = hidden & ((p > 0.65) | (p < 0.196))  # outside ROS 1's unknown band
    assert decided.sum() > 20
    unknown = load_ros_map(tmp_path / "u" / "ros" / "map.yaml", flavor="ros1").occupancy
    predicted = load_ros_map(tmp_path / "p" / "ros" / "map.yaml", flavor="ros1").occupancy
    assert (unknown[hidden] == -1).all()
    assert (predicted[decided] != -1).all() and ((predicted[decided] == 100) == (p[decided] > 0.65)).all()
    img_u = np.asarray(Image.open(tmp_path / "u" / "map.png"))[::-1].reshape(-1, 3)
    img_p = np.asarray(Image.open(tmp_path / "p" / "map.png"))[::-1].reshape(-1, 3)
    assert (img_u[hidden] == img_u[hidden][0]).all() and len(np.unique(img_p[hidden], axis=0)) > 2
    np.testing.assert_array_equal(img_u[~hidden], img_p[~hidden])


def test_an_interrupted_map_under_a_prior_that_changed_starts_afresh(sim_dataset, tmp_path, monkeypatch, capsys):
    """A prior of one's own changed under the same name (tables counted again) is another chain: the same command
    starts afresh instead of refusing the old checkpoint, and a note names the interrupted run left behind."""
    import ogm_ppl.inference.mcmc as mcmc
    from ogm_ppl.priors import IndependentPrior, named, register_prior, unregister_prior

    register_prior("cli_probe_prior", lambda shape, tables: IndependentPrior(0.3, int(np.prod(shape))))
    try:
        argv = ["map", str(sim_dataset), "--method", "gibbs", "--prior", "cli_probe_prior", "--sweeps", "12"]
        argv += ["--param", "checkpoint_every=2", "--out", str(tmp_path / "o")]
        real = mcmc.run_gibbs
        monkeypatch.setattr(mcmc, "run_gibbs", lambda *a, **kw: real(*a, **{**kw, "stop_after": 4}))
        assert main(argv) == 130
        assert len(list((tmp_path / "o").glob(".checkpoints/*/chain-0/gibbs.npz"))) == 1
        monkeypatch.setattr(mcmc, "run_gibbs", real)
        monkeypatch.setitem(
            named._FACTORIES, "cli_probe_prior", lambda shape, tables: IndependentPrior(0.4, int(np.prod(shape)))
        )
        capsys.readouterr()
        assert main(argv) == 0
        err = capsys.readouterr().err
        assert "resumes from its checkpoint" not in err and "keeps the checkpoints of 1 other interrupted" in err
    finally:
        unregister_prior("cli_probe_prior")


def test_a_square_number_of_cells_as_patch_gets_a_note_on_the_square_patch(sim_dataset, tmp_path, capsys):
    """``--patch 9`` is a 1 x 9 run (as the API's int L); "L = 9" in the thesis's 2D experiments is 3 x 3: a note
    says which flag gives that."""
    argv = ["map", str(sim_dataset), "--method", "gibbs", "--sweeps", "2", "--warmup", "0", "--out"]
    assert main([*argv, str(tmp_path / "a"), "--patch", "9"]) == 0
    assert "note: --patch 9 is a run of 9 cells in one row; square 3 x 3 patches" in capsys.readouterr().err
    assert load_map(tmp_path / "a" / "map.npz")["settings"]["method_details"]["patch"] == 9
    assert main([*argv, str(tmp_path / "b"), "--patch", "3x3"]) == 0
    assert "note:" not in capsys.readouterr().err


def test_an_image_given_as_a_log_is_named_as_such(tmp_path, capsys):
    from PIL import Image

    png = tmp_path / "plan.png"
    Image.fromarray(np.full((8, 8), 255, np.uint8)).save(png)
    pgm = tmp_path / "plan.pgm"
    pgm.write_bytes(b"P5\n8 8\n255\n" + bytes(64))
    for path, kind in ((png, "PNG"), (pgm, "PGM")):
        assert main(["map", str(path), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert f"{path}: a {kind} image (a floor plan?), not a log, bag or dataset file" in err
        assert "ogm-ppl simulate --map PLAN.png" in err
