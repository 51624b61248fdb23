"""Probes: malformed inputs of every reader, spec, option and artefact, each run in a fresh process.

Every probe is a snippet that hands the library one bad input. It is classified as

* ``clear``: a ``ValueError`` / ``TypeError`` (or subclass; or a warning made an error) raised from ogm_ppl's
  own code, or an ``OSError`` that names the file (``FileNotFoundError`` of a missing path);
* ``deep``: an exception raised inside a third-party library (torch, numpy, ...), or of another type;
* ``silent``: the snippet returned (the bad input was accepted);
* ``crash``: the process died (signal, allocator abort);
* ``hang``: no answer within :data:`TIMEOUT_S` seconds.

Probes whose right answer is a warning turn that warning into an error. Probes run in batches (one process
for several, a timer per probe; a crashed or hung process is restarted after the probe that killed it).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the checkout whose ogm_ppl the probes import (another one, e.g. an older commit, to compare counts)
TARGET = Path(os.environ.get("OGM_PPL_PROBE_ROOT", ROOT))
TIMEOUT_S = 15

PRELUDE = """
import os, sys, json, math, gzip, tempfile, warnings, traceback, signal
import numpy as np, torch
D = tempfile.mkdtemp()
def P(name): return os.path.join(D, name)
def toy_model(K=12, prior=None):
    from ogm_ppl import GaussianRange, OccupancyModel, raycast
    from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
    from ogm_ppl.priors import IndependentPrior
    toy = toy_1d(num_cells=K, readings=THESIS_TOY_READINGS[:2], wall=6)
    return OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(1.0), prior or IndependentPrior(0.3, K))
def flaser_log(path, n=300, gz=False):
    lines = [f"FLASER 3 {1 + i % 7}.0 2.0 81.83 0 0 0 0 0 0 {i}.0 host {i}.0" for i in range(n)]
    data = ("\\n".join(lines) + "\\n").encode()
    open(path, "wb").write(gzip.compress(data) if gz else data)
    return path
def shipped(name):
    from importlib import resources
    return json.loads((resources.files("ogm_ppl") / "fitted" / f"delta_{name}.json").read_text())
def write_json(path, rec):
    open(path, "w").write(json.dumps(rec)); return path
def smoke():
    import tomllib
    return tomllib.loads(open(os.path.join(ROOT, "experiments", "specs", "smoke.toml")).read())
"""

#: name -> snippet (run after PRELUDE; raising is the right answer)
PROBES: dict[str, str] = {
    # grid and maps
    "grid-fractional-shape": "from ogm_ppl import Grid; Grid((20.5, 20))",
    "grid-string-shape": "from ogm_ppl import Grid; Grid(('20', 20))",
    "map-estimate-init-half": "from ogm_ppl.inference.exact.map_estimate import map_estimate\n"
    "map_estimate(toy_model(), init=np.full(12, 0.5))",
    "map-estimate-init-nan": "from ogm_ppl.inference.exact.map_estimate import map_estimate\n"
    "map_estimate(toy_model(), init=np.full(12, np.nan))",
    "patch-map-reference-half": "from ogm_ppl.inference.patch_map.maps import offline_patch_map\n"
    "offline_patch_map(toy_model(), patch=2, reference=np.full(12, 0.5))",
    "log-joint-string": "toy_model().log_joint('0' * 12)",
    "log-joint-short": "toy_model().log_joint(torch.zeros(5))",
    # CARMEN logs
    "carmen-nan-threshold": "from ogm_ppl.datasets import read_carmen\n"
    "read_carmen(flaser_log(P('a.log')), no_return_threshold=float('nan'))",
    "carmen-negative-usable": "from ogm_ppl.datasets import read_carmen\n"
    "read_carmen(flaser_log(P('a.log')), max_usable_range=-5)",
    "carmen-string-usable": "from ogm_ppl.datasets import read_carmen\n"
    "read_carmen(flaser_log(P('a.log')), max_usable_range='20')",
    "carmen-flipped-gzip-lenient-warns": "from ogm_ppl.datasets import read_carmen\n"
    "from ogm_ppl.datasets.carmen import CarmenReadWarning\n"
    "warnings.simplefilter('error', CarmenReadWarning)\n"
    "p = flaser_log(P('a.log.gz'), n=2000, gz=True); b = bytearray(open(p, 'rb').read()); b[len(b) // 2] ^= 0xFF\n"
    "open(p, 'wb').write(bytes(b)); read_carmen(p, strict=False)",
    "carmen-binary-garbage": "from ogm_ppl.datasets import read_carmen\n"
    "open(P('g.log'), 'wb').write(bytes(range(256)) * 40); read_carmen(P('g.log'))",
    "carmen-empty": "from ogm_ppl.datasets import read_carmen\nopen(P('e.log'), 'w').close(); read_carmen(P('e.log'))",
    "carmen-missing": "from ogm_ppl.datasets import read_carmen\nread_carmen(P('nope.log'))",
    # dataset files
    "dataset-no-scans": "from ogm_ppl import Scans\nfrom ogm_ppl.datasets import load_dataset, save_dataset\n"
    "p = save_dataset(P('d.npz'), Scans([0.0, 0.0, 0.0], [0.0], [1.0], max_range=4.0))\n"
    "a = dict(np.load(p)); a.update(poses=np.zeros((0, 3)), angles=np.zeros((0, 1)), ranges=np.zeros((0, 1)),"
    " valid=np.zeros((0, 1), bool)); np.savez(p, **a); load_dataset(p)",
    "dataset-text-sigma": "from ogm_ppl import Scans\nfrom ogm_ppl.datasets import load_dataset, save_dataset\n"
    "load_dataset(save_dataset(P('d.npz'), Scans([0.0, 0.0, 0.0], [0.0], [1.0], max_range=4.0),"
    " settings={'sigma_cells': 'abc'}))",
    "dataset-pickle": "from ogm_ppl.datasets import load_dataset\n"
    "np.savez(P('d.npz'), format=np.array([{'a': 1}], dtype=object)); load_dataset(P('d.npz'))",
    "dataset-truncated": "from ogm_ppl import Scans\nfrom ogm_ppl.datasets import load_dataset, save_dataset\n"
    "p = save_dataset(P('d.npz'), Scans([0.0, 0.0, 0.0], [0.0], [1.0], max_range=4.0))\n"
    "b = open(p, 'rb').read(); open(p, 'wb').write(b[: len(b) // 2]); load_dataset(p)",
    # Delta artefacts
    "delta-negative-F": "from ogm_ppl.models import load_delta\n"
    "r = shipped('neural_opt'); r['delta']['fixed']['F'] = -75\n"
    "load_delta(write_json(P('d.json'), r))",
    "delta-huge-hidden": "from ogm_ppl.models import load_delta\nr = shipped('neural_opt');"
    " r['delta']['fixed']['hidden'] = 10**9\nload_delta(write_json(P('d.json'), r))",
    "delta-elfes-negative-max-kappa": "from ogm_ppl.models import load_delta\nr = shipped('elfes_opt');"
    " r['delta']['fixed']['max_kappa'] = -3\nload_delta(write_json(P('d.json'), r))",
    "delta-nan-training": "from ogm_ppl.models import load_delta\n"
    "r = shipped('p21'); r['training']['sigma'] = float('nan')\n"
    "load_delta(write_json(P('d.json'), r))",
    "delta-truncated": "from ogm_ppl.models import load_delta\n"
    "open(P('d.json'), 'w').write(json.dumps(shipped('p21'))[:100]); load_delta(P('d.json'))",
    # experiment specs
    "spec-name-dotdot": "from ogm_ppl.experiment import parse_spec\n"
    "d = smoke(); d.setdefault('experiment', {})['name'] = '../x'\n"
    "parse_spec(d, 'smoke.toml')",
    "spec-name-absolute": "from ogm_ppl.experiment import parse_spec\nd = smoke();"
    " d.setdefault('experiment', {})['name'] = '/tmp/x'\nparse_spec(d, 'smoke.toml')",
    "spec-reader-string": "from ogm_ppl.experiment import parse_spec\nd = smoke(); d['datasets'].append({'name': 'x',"
    " 'kind': 'log', 'path': flaser_log(P('a.log')), 'reader': {'max_usable_range': '20'}})\n"
    "parse_spec(d, 'smoke.toml')",
    "spec-truncated-toml": "from ogm_ppl.experiment import load_spec\n"
    "t = open(os.path.join(ROOT, 'experiments', 'specs', 'smoke.toml')).read()\n"
    "open(P('s.toml'), 'w').write(t[: len(t) // 3]); load_spec(P('s.toml'))",
    "spec-binary": "from ogm_ppl.experiment import load_spec\nopen(P('s.toml'), 'wb').write(b'\\xff\\xfe\\x00' * 50)\n"
    "load_spec(P('s.toml'))",
    "spec-datasets-not-list": "from ogm_ppl.experiment import parse_spec\nd = smoke(); d['datasets'] = {'a': 1}\n"
    "parse_spec(d, 'smoke.toml')",
    # prior tables
    "tables-garbage": "from ogm_ppl.priors.tables import load_tables\n"
    "open(P('t.npz'), 'wb').write(b'PK\\x03\\x04' + bytes(100)); load_tables(P('t.npz'))",
    "tables-foreign-npz": "from ogm_ppl.priors.tables import load_tables\n"
    "np.savez(P('t.npz'), x=np.zeros(3)); load_tables(P('t.npz'))",
    "tables-pickle": "from ogm_ppl.priors.tables import load_tables\n"
    "np.savez(P('t.npz'), codes=np.array([object()], dtype=object)); load_tables(P('t.npz'))",
    # Gibbs checkpoints
    "checkpoint-garbage": "from ogm_ppl.inference import CellGibbs, run_gibbs\n"
    "open(P('c.npz'), 'wb').write(b'junk' * 10)\n"
    "run_gibbs(CellGibbs(toy_model()), 5, checkpoint=P('c.npz'), progress=False)",
    "checkpoint-foreign-npz": "from ogm_ppl.inference import CellGibbs, run_gibbs\n"
    "np.savez(P('c.npz'), x=np.zeros(2))\n"
    "run_gibbs(CellGibbs(toy_model()), 5, checkpoint=P('c.npz'), progress=False)",
    "checkpoint-other-warmup": "from ogm_ppl.inference import CellGibbs, run_gibbs\nm = toy_model()\n"
    "run_gibbs(CellGibbs(m), 20, warmup=5, checkpoint=P('c.npz'), stop_after=3, progress=False)\n"
    "run_gibbs(CellGibbs(m), 20, warmup=0, checkpoint=P('c.npz'), progress=False)",
    # ROS maps
    "rosmap-yaml-garbage": "from ogm_ppl.rosmap import load_ros_map\n"
    "open(P('m.yaml'), 'w').write('image: [unclosed\\n'); load_ros_map(P('m.yaml'))",
    "rosmap-yaml-python-tag": "from ogm_ppl.rosmap import load_ros_map\n"
    "open(P('m.yaml'), 'w').write('image: !!python/object/apply:os.system [\"true\"]\\nresolution: 0.05\\n"
    "origin: [0, 0, 0]\\n'); load_ros_map(P('m.yaml'))",
    "rosmap-missing-image": "from ogm_ppl.rosmap import load_ros_map\n"
    "open(P('m.yaml'), 'w').write('image: m.pgm\\nresolution: 0.05\\norigin: [0, 0, 0]\\nnegate: 0\\n"
    "occupied_thresh: 0.65\\nfree_thresh: 0.196\\n'); load_ros_map(P('m.yaml'))",
    "rosmap-truncated-pgm": "from ogm_ppl.rosmap import load_ros_map\n"
    "open(P('m.pgm'), 'wb').write(b'P5\\n100 100\\n255\\n' + bytes(50))\n"
    "open(P('m.yaml'), 'w').write('image: m.pgm\\nresolution: 0.05\\norigin: [0, 0, 0]\\nnegate: 0\\n"
    "occupied_thresh: 0.65\\nfree_thresh: 0.196\\n'); load_ros_map(P('m.yaml'))",
    "rosmap-negative-resolution": "from ogm_ppl.rosmap import load_ros_map\n"
    "open(P('m.pgm'), 'wb').write(b'P5\\n4 4\\n255\\n' + bytes(16))\n"
    "open(P('m.yaml'), 'w').write('image: m.pgm\\nresolution: -0.05\\norigin: [0, 0, 0]\\nnegate: 0\\n"
    "occupied_thresh: 0.65\\nfree_thresh: 0.196\\n'); load_ros_map(P('m.yaml'))",
    # methods
    "gibbs-patch-4x5-64x64": "from ogm_ppl.datasets.simple2d import simple_2d_example\n"
    "from ogm_ppl.methods import MapProblem, RunContext, get_method\nex = simple_2d_example(num_beams=45)\n"
    "m = get_method('gibbs'); m.run(m.parse({'patch': [4, 5]}), MapProblem(ex.grid, ex.scans, sigma_cells=3.0),"
    " RunContext(seed=0))",
}

RUNNER = """
import json, os, signal, sys, traceback
ROOT = {root!r}
exec(compile({prelude!r}, "<prelude>", "exec"))
probes = json.loads(sys.stdin.read())
class _Hang(BaseException):
    pass
def _alarm(*a):
    raise _Hang()
signal.signal(signal.SIGALRM, _alarm)
import tempfile
for name, code in probes:
    D = tempfile.mkdtemp()  # a fresh folder per probe (P() writes there)
    print(json.dumps({{"start": name}}), flush=True)
    signal.alarm({timeout})
    try:
        exec(compile(code, name, "exec"), dict(globals()))
        out = {{"name": name, "outcome": "silent"}}
    except _Hang:
        out = {{"name": name, "outcome": "hang"}}
    except Exception as e:
        tb = traceback.extract_tb(e.__traceback__)
        last = tb[-1].filename if tb else ""
        ours = os.sep + "ogm_ppl" + os.sep in last or (isinstance(e, OSError) and bool(e.filename))
        kind = isinstance(e, (ValueError, TypeError, Warning)) or (isinstance(e, OSError) and bool(e.filename))
        out = {{"name": name, "outcome": "clear" if ours and kind else "deep",
               "message": (type(e).__name__ + ": " + str(e))[:300], "where": last}}
    finally:
        signal.alarm(0)
    print(json.dumps(out), flush=True)
"""


def run_probes(probes: dict[str, str], timeout: int = TIMEOUT_S) -> dict[str, dict]:
    """Run ``probes`` in as few fresh processes as crashes allow; ``name -> {outcome, message, where}``."""
    env = {**os.environ, "PYTHONPATH": str(TARGET), "PYTHONWARNINGS": "ignore"}
    code = RUNNER.format(root=str(TARGET), prelude=PRELUDE, timeout=timeout)
    todo = list(probes.items())
    results: dict[str, dict] = {}
    while todo:
        try:
            p = subprocess.run(
                [sys.executable, "-c", code],
                input=json.dumps(todo),
                capture_output=True,
                text=True,
                env=env,
                cwd=TARGET,
                timeout=timeout * len(todo) + 60,
            )
            lines = p.stdout.splitlines()
        except subprocess.TimeoutExpired as e:
            out = e.stdout.decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
            lines = out.splitlines()
        started = None
        for line in lines:
            rec = json.loads(line)
            if "start" in rec:
                started = rec["start"]
            else:
                results[rec["name"]] = rec
                started = None
        if started is not None and started not in results:  # the process died in this probe
            results[started] = {"name": started, "outcome": "crash"}
        todo = [(n, c) for n, c in todo if n not in results]
        if todo and started is None:  # died before starting anything: do not loop forever
            for n, _ in todo:
                results[n] = {"name": n, "outcome": "crash", "message": p.stderr[-300:]}
            todo = []
    return results


def _table(results: dict[str, dict]) -> str:
    counts = {k: 0 for k in ("clear", "silent", "deep", "crash", "hang")}
    for r in results.values():
        counts[r["outcome"]] += 1
    rows = [f"{'probe':40s} outcome  message"]
    rows += [f"{n:40s} {r['outcome']:8s} {r.get('message', '')[:110]}" for n, r in sorted(results.items())]
    rows.append("counts: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    return "\n".join(rows)


def test_every_probe_gives_a_clear_error():
    results = run_probes(PROBES)
    print("\n" + _table(results))
    bad = {n: r for n, r in results.items() if r["outcome"] != "clear"}
    assert not bad, textwrap.indent(_table(bad), "  ")


if __name__ == "__main__":  # python tests/test_probes.py: the table only
    print(_table(run_probes(PROBES)))
