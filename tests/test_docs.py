"""The README's quick start and every docstring example run as written; the generated tables of the
README and the docs equal what tools/gen_docs_tables.py builds from the committed JSON snapshots (the tool is
run as its users run it, in a fresh interpreter)."""

import doctest
import importlib
import json
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest

import ogm_ppl

matplotlib.use("Agg")
ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"

MODULES = sorted(m.name for m in pkgutil.walk_packages(ogm_ppl.__path__, "ogm_ppl.") if not m.name.endswith("__main__"))


def test_readme_quick_start_runs(tmp_path, monkeypatch):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "the README has a Python quick start"
    # the examples write into out/ and read the shared data as ../shared, as from the repository root
    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "shared").symlink_to(ROOT.parent / "shared")
    monkeypatch.chdir(work)
    namespace = {}
    for block in blocks:  # one namespace, top to bottom, as a reader would run them
        exec(compile(block, "README.md", "exec"), namespace)


GUIDE = ["guide/model.md", "guide/priors.md", "guide/inference.md", "guide/real_data.md", "guide/exploration.md"]


def test_guide_examples_run(tmp_path, monkeypatch):
    """The guide's Python blocks, page after page in one namespace, as a reader would run them."""
    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "shared").symlink_to(ROOT.parent / "shared")
    monkeypatch.chdir(work)
    namespace = {}
    for page in GUIDE:
        blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / page).read_text(), flags=re.S)
        assert blocks, page
        for block in blocks:
            exec(compile(block, page, "exec"), namespace)


def test_extending_page_examples_run_and_build_what_their_contracts_test():
    """The extending page's blocks, top to bottom in one namespace, with its placeholders (``MySensor``,
    ``MyKernel``, ``MyPrior``: the reader's own classes) stood in by shipped ones and the page's own prior;
    each contract class they define builds its object (the suites themselves run in
    tests/priors/test_extending.py and the contract tests)."""
    from ogm_ppl import GaussianRange
    from ogm_ppl.inference.mcmc import PatchGibbs
    from ogm_ppl.priors import unregister_prior
    from ogm_ppl.testing import KernelContract, MethodContract, PriorContract, SensorContract

    namespace = {
        "MySensor": lambda sigma, p_rand=0.0, p_short=0.0: GaussianRange(sigma, p_rand),  # options dropped
        "MyKernel": lambda model, region=None: PatchGibbs(model, 2, region=region),
        "MyPrior": lambda shape: namespace["CheckerboardPrior"](shape),  # the page's own prior
    }
    from ogm_ppl.priors import named

    page = ROOT / "docs" / "extending.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
    before = named._FACTORIES.pop("toy_checker", None)  # tests/priors/test_extending.py registers the same kind
    try:
        for block in blocks:
            exec(compile(block, str(page), "exec"), namespace)
        tests = {k: v for k, v in namespace.items() if k.startswith("Test") and isinstance(v, type)}
        kinds = {
            c.__name__: sorted(n for n, t in tests.items() if issubclass(t, c))
            for c in (PriorContract, SensorContract, KernelContract, MethodContract)
        }
        assert all(kinds.values()), kinds
        for name in kinds["PriorContract"]:
            assert tests[name]().make_prior(5).log_prob(np.zeros(5)).shape == ()
        for name in kinds["SensorContract"]:
            assert isinstance(tests[name]().make_sensor(), GaussianRange)
        from ogm_ppl.sensors import sensor_by_name

        assert repr(sensor_by_name("my_sensor:p_short=0.2", 2.5, 0.1)) == "GaussianRange(sigma=2.5, p_rand=0.1)"
        from ogm_ppl.methods import MapProblem, RunContext, get_method
        from ogm_ppl.testing.kernels import enumerable_2d_data

        chain = get_method("my_chain")  # the page's kernel method runs as the samplers run
        r = chain.run(chain.parse({"sweeps": 20}), MapProblem(*enumerable_2d_data(), 0.9), RunContext(seed=0))
        assert r.probabilities.shape == (8,) and r.details["kernel"] == "MetropolisCell"
        for name in kinds["KernelContract"]:
            t = tests[name]()
            for model in (t.problem_1d(), t.problem_2d()):
                assert t.make_kernel(model).model is model
    finally:
        unregister_prior(namespace.get("KIND", "toy_checker"))
        if before is not None:
            named.register_prior("toy_checker", before)
        from ogm_ppl.methods import unregister_method

        unregister_method("endpoints")
        unregister_method("my_chain")
        from ogm_ppl.sensors import unregister_sensor

        unregister_sensor("my_sensor")
        from ogm_ppl.inputs import unregister_input_kind

        unregister_input_kind("csv_scans")


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0


def _tool(*args: object) -> subprocess.CompletedProcess:
    """``python tools/gen_docs_tables.py ARGS`` from the checkout's root (output captured as text)."""
    cmd = [sys.executable, str(ROOT / "tools" / "gen_docs_tables.py"), *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, check=False, timeout=600)


def _tables() -> dict[str, str]:
    """Each generated table's name and its snapshot's (``gen_docs_tables.py list``)."""
    r = _tool("list")
    assert r.returncode == 0, r.stderr
    return dict(line.split() for line in r.stdout.splitlines())


def _rows(markdown: str) -> list[list[str]]:
    """The rows of a table ``gen_docs_tables.py show`` printed (header first, the separator left out), split
    into cells at the pipes that are not escaped."""
    lines = [line for line in markdown.splitlines() if line.startswith("| ")]
    return [[c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]] for line in lines]


def _snapshot(name: str) -> dict:
    return json.loads((RESULTS / f"{name}.json").read_text())


def test_readme_generated_blocks_equal_the_snapshots():
    text = (ROOT / "README.md").read_text()
    names = re.findall(r"<!-- generated: ([a-z0-9_]+) -->", text)
    assert "headline" in names and set(names) <= set(_tables())
    r = _tool("readme", "--check")  # every block equals the table built from its snapshot
    assert (r.returncode, r.stdout.strip()) == (0, "stale: none"), (
        f"README blocks are stale: run python tools/gen_docs_tables.py readme\n{r.stdout}{r.stderr}"
    )


def test_every_snapshot_is_stamped_and_every_table_builds():
    snaps = sorted(p.stem for p in RESULTS.glob("*.json"))
    assert snaps
    for name in snaps:
        prov = _snapshot(name)["provenance"]
        assert prov["command"] and re.fullmatch(r"[0-9a-f]{40}(-dirty)?", prov["commit"]), (name, prov)
        assert {"cpu", "cores", "python", "torch", "numba"} <= set(prov["machine"]), name
    for name, snap in _tables().items():
        if snap in snaps:
            r = _tool("show", name)
            assert r.returncode == 0, (name, r.stderr)
            rows = _rows(r.stdout)
            assert len(rows) > 1 and all(len(row) == len(rows[0]) for row in rows), name


def test_every_public_module_is_in_the_api_reference():
    """Each module (not a package) whose dotted name has no private part has an ``automodule`` in docs/api."""
    text = "".join(p.read_text() for p in (ROOT / "docs" / "api").glob("*.rst"))
    documented = set(re.findall(r"automodule:: (\S+)", text))
    public = [
        m.name
        for m in pkgutil.walk_packages(ogm_ppl.__path__, "ogm_ppl.")
        if not m.ispkg and not any(part.startswith("_") for part in m.name.split(".")[1:])
    ]
    assert len(public) > 50
    assert sorted(set(public) - documented) == []


def test_every_table_a_page_shows_has_a_snapshot():
    shown = set()
    for page in (ROOT / "docs").rglob("*.md"):
        shown |= set(re.findall(r"```\{ogm-table\} ([a-z0-9_]+)", page.read_text()))
    assert {"headline", "bench_ogm"} <= shown
    tables = _tables()
    for name in shown:
        assert name in tables, name
        assert (RESULTS / f"{tables[name]}.json").is_file(), name


def test_snapshot_stamps_an_unstamped_result_and_the_readme_follows(tmp_path):
    results = tmp_path / "results"
    src = tmp_path / "bench_exact.json"
    doc = _snapshot("bench_exact")
    doc.pop("provenance")
    doc["brute_force"][0]["seconds"] = 123.0
    src.write_text(json.dumps(doc))
    r = _tool("snapshot", src, "--results", results)
    assert r.returncode == 2 and "--command" in r.stderr
    r = _tool("snapshot", src, "--command", "python benchmarks/bench_exact.py", "--results", results)
    assert r.returncode == 0, r.stderr
    stamped = json.loads((results / "bench_exact.json").read_text())
    assert stamped["provenance"]["command"] == "python benchmarks/bench_exact.py"
    r = _tool("snapshot", results / "bench_exact.json", "--command", "x", "--results", tmp_path)
    assert r.returncode == 2 and "already stamped" in r.stderr

    readme = tmp_path / "README.md"
    readme.write_text("intro\n<!-- generated: bench_exact -->\n| stale |\n<!-- end generated -->\nend\n")
    check = ("readme", "--readme", readme, "--results", results, "--check")
    r = _tool(*check)
    assert (r.returncode, r.stdout.strip()) == (1, "stale: bench_exact")
    assert "| stale |" in readme.read_text()  # check writes nothing
    r = _tool(*check[:-1])
    assert (r.returncode, r.stdout.strip()) == (0, "updated: bench_exact")
    text = readme.read_text()
    assert "| brute force, K = 16 | 6 | 123 |" in text and "`python benchmarks/bench_exact.py` at commit" in text
    assert text.startswith("intro\n") and text.endswith("<!-- end generated -->\nend\n")
    assert _tool(*check).returncode == 0


def test_snapshot_can_leave_out_the_per_dataset_curves_and_the_tables_stay(tmp_path):
    results = tmp_path / "results"
    src = RESULTS / "table_6_4_small.json"
    doc = _snapshot("table_6_4_small")
    kept = [
        {b: {k: v for k, v in x.items() if k != "curve"} if isinstance(x, dict) else x for b, x in r.items()}
        for r in doc["scores"]
    ]
    r = _tool("snapshot", src, "--results", results, "--drop-curves")
    assert r.returncode == 0, r.stderr
    small = json.loads((results / "table_6_4_small.json").read_text())
    assert small["scores"] == kept and small["pooled"] == doc["pooled"]
    assert "per-dataset" in small["provenance"]["dropped"]
    assert {k: v for k, v in small["provenance"].items() if k != "dropped"} == doc["provenance"]
    assert (results / "table_6_4_small.json").stat().st_size < src.stat().st_size
    assert _rows(_tool("show", "table_6_4_small", "--results", results).stdout) == _rows(
        _tool("show", "table_6_4_small").stdout
    )


def _split_by_algorithm(doc: dict, algorithms: set[str]) -> tuple[dict, dict]:
    """``doc`` cut in two experiment summaries: the rows of ``algorithms``, and the rest."""

    def part(keep) -> dict:
        out = {k: v for k, v in doc.items() if k not in ("scores", "pooled", "runs")}
        for key in ("scores", "pooled", "runs"):
            out[key] = [r for r in doc[key] if keep(r["algorithm"])]
        return out

    return part(lambda a: a not in algorithms), part(lambda a: a in algorithms)


def test_merge_adds_a_later_runs_algorithms_and_refuses_other_data(tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    doc = _snapshot("table_6_4_small")
    later = {doc["pooled"][-1]["algorithm"]}
    first, second = _split_by_algorithm(doc, later)
    into = results / "table_6_4_small.json"
    into.write_text(json.dumps(first))
    src = tmp_path / "metrics.json"
    unstamped = {k: v for k, v in second.items() if k != "provenance"}
    unstamped["datasets"] = [{**d, "seconds": 1.0} for d in unstamped["datasets"]]  # times may differ
    src.write_text(json.dumps(unstamped))
    before = into.read_text()

    def refused(change, match: str) -> None:
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps(change(json.loads(src.read_text()))))
        r = _tool("merge", bad, "--into", "table_6_4_small", "--command", "cmd", "--results", results)
        assert r.returncode == 2 and match in r.stderr, r.stderr
        assert into.read_text() == before  # nothing written

    refused(lambda d: {**d, "seed": d["seed"] + 1}, "seed differs")
    refused(lambda d: {**d, "datasets": [{**d["datasets"][0], "scans": -1}, *d["datasets"][1:]]}, "datasets differs")
    refused(lambda d: {**d, "runs": d["runs"] + [doc["runs"][0]]}, "both hold")
    cmd = "ogm-ppl experiment spec --algorithms x"
    r = _tool("merge", src, "--into", "table_6_4_small", "--command", cmd, "--results", results)
    assert r.returncode == 0, r.stderr
    merged = json.loads(into.read_text())
    for key in ("scores", "pooled", "runs"):
        assert sorted(map(json.dumps, merged[key])) == sorted(map(json.dumps, doc[key]))
    prov = merged["provenance"]
    assert prov["command"] == f"{doc['provenance']['command']}; then ogm-ppl experiment spec --algorithms x"
    before_parts = doc["provenance"].get("parts", [doc["provenance"]])  # the snapshot may be a merge already
    assert prov["parts"][:-1] == before_parts and prov["parts"][-1]["command"].endswith("--algorithms x")
    shown = _tool("show", "table_6_4_small", "--results", results).stdout
    assert [row[0] for row in _rows(shown)[1:]] == [p["algorithm"] for p in doc["pooled"]]
    line = shown.strip().splitlines()[-1].rpartition(". From `")[2]  # the provenance line under the table
    assert line.count(" on ") == len(before_parts) + 1 and before_parts[0]["commit"][:12] in line


def test_merge_adds_an_error_splits_algorithms(tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    doc = _snapshot("table_6_4_errors")
    name = sorted(doc["algorithms"])[-1]
    first = {**doc, "algorithms": {k: v for k, v in doc["algorithms"].items() if k != name}}
    (results / "table_6_4_errors.json").write_text(json.dumps(first))
    src = tmp_path / "errors.json"
    later = {k: v for k, v in doc.items() if k not in ("provenance", "algorithms")}
    src.write_text(json.dumps({**later, "algorithms": {name: doc["algorithms"][name]}}))
    other = tmp_path / "other.json"
    other.write_text(json.dumps({**later, "cells": {"touched": 1, "untouched": 2}, "algorithms": {"x": {}}}))
    merge = ("merge", "--into", "table_6_4_errors", "--results", results, "--command")
    r = _tool(*merge, "cmd", other)
    assert r.returncode == 2 and "cells differs" in r.stderr
    r = _tool(*merge, "python experiments/table_6_4_errors.py x", src)
    assert r.returncode == 0, r.stderr
    merged = json.loads((results / "table_6_4_errors.json").read_text())
    assert merged["algorithms"] == doc["algorithms"]
    mine, shipped = (_rows(_tool("show", "table_6_4_errors", *x).stdout) for x in (("--results", results), ()))
    assert mine[0] == shipped[0] and sorted(mine[1:]) == sorted(shipped[1:])


def test_merge_adds_an_explorations_rules_and_recomputes_its_summary(tmp_path):
    from ogm_ppl.experiment.active import summarise

    results = tmp_path / "results"
    results.mkdir()
    doc = _snapshot("active_full")
    methods = [r["method"] for r in doc["summary"]]
    late = set(methods[-2:])
    first = {**doc, "runs": [r for r in doc["runs"] if r["method"] not in late]}
    first["summary"] = summarise(first["runs"], methods[:-2])
    into = results / "active_full.json"
    into.write_text(json.dumps(first))
    later = {k: v for k, v in doc.items() if k != "provenance"}
    later["runs"] = [r for r in doc["runs"] if r["method"] in late]
    later["summary"] = summarise(later["runs"], methods[-2:])  # its ratios are against its own first rule
    src = tmp_path / "metrics.json"
    src.write_text(json.dumps(later))
    before = into.read_text()
    merge = ("merge", "--into", "active_full", "--results", results, "--command")
    bad = tmp_path / "bad.json"
    moved = [{**r, "start": [0, 0]} if i == 0 else r for i, r in enumerate(later["runs"])]
    bad.write_text(json.dumps({**later, "runs": moved}))
    r = _tool(*merge, "cmd", bad)
    assert r.returncode == 2 and "starts differs" in r.stderr
    bad.write_text(json.dumps({**later, "plans": later["plans"][:-1]}))
    r = _tool(*merge, "cmd", bad)
    assert r.returncode == 2 and "plans differs" in r.stderr
    assert into.read_text() == before
    r = _tool(*merge, "ogm-ppl experiment active.toml --algorithms x", src)
    assert r.returncode == 0, r.stderr
    merged = json.loads(into.read_text())
    assert json.dumps(merged["summary"]) == json.dumps(doc["summary"])  # ratios against the snapshot's first rule
    mine, shipped = (_rows(_tool("show", "active_full", *x).stdout) for x in (("--results", results), ()))
    assert mine == shipped


def test_readme_requirements_name_every_dependency_at_its_lower_bound():
    """The README's requirements line lists each of pyproject.toml's dependencies with its lower bound."""
    import tomllib

    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    text = " ".join((ROOT / "README.md").read_text().split())
    for dep in deps:
        req = dep.split(";")[0].strip()
        name, _, low = req.partition(">=")
        assert f"{name} >= {low}" in text, f"README's requirements lack {req!r}"
