"""The README's quick start and every docstring example run as written; the generated tables of the
README and the docs equal what tools/gen_docs_tables.py builds from the committed JSON snapshots."""

import doctest
import importlib
import json
import pkgutil
import re
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest

import ogm_ppl

matplotlib.use("Agg")
ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
import gen_docs_tables  # noqa: E402

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


def test_readme_generated_blocks_equal_the_snapshots():
    text = (ROOT / "README.md").read_text()
    names = re.findall(r"<!-- generated: ([a-z0-9_]+) -->", text)
    assert "headline" in names
    for name in names:
        body = re.search(rf"<!-- generated: {name} -->\n(.*?)<!-- end generated -->", text, re.S)[1]
        assert body == gen_docs_tables.readme_block(name), (
            f"README block {name!r} is stale: run python tools/gen_docs_tables.py readme"
        )
    assert gen_docs_tables.update_readme(ROOT / "README.md", check=True) == []


def test_every_snapshot_is_stamped_and_every_table_builds():
    snaps = sorted(p.stem for p in gen_docs_tables.RESULTS.glob("*.json"))
    assert snaps
    for name in snaps:
        prov = gen_docs_tables.load_snapshot(name)["provenance"]
        assert prov["command"] and re.fullmatch(r"[0-9a-f]{40}(-dirty)?", prov["commit"]), (name, prov)
        assert {"cpu", "cores", "python", "torch", "numba"} <= set(prov["machine"]), name
    for name, (snap, _) in gen_docs_tables.TABLES.items():
        if snap in snaps:
            t = gen_docs_tables.table(name)
            assert t.rows and all(len(r) == len(t.header) for r in t.rows), name


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
    for name in shown:
        assert name in gen_docs_tables.TABLES, name
        assert (gen_docs_tables.RESULTS / f"{gen_docs_tables.TABLES[name][0]}.json").is_file(), name


def test_snapshot_stamps_an_unstamped_result_and_the_readme_follows(tmp_path):
    results = tmp_path / "results"
    src = tmp_path / "bench_exact.json"
    doc = gen_docs_tables.load_snapshot("bench_exact")
    doc.pop("provenance")
    doc["brute_force"][0]["seconds"] = 123.0
    src.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="--command"):
        gen_docs_tables.snapshot(src, results=results)
    gen_docs_tables.snapshot(src, command="python benchmarks/bench_exact.py", results=results)
    stamped = gen_docs_tables.load_snapshot("bench_exact", results)
    assert stamped["provenance"]["command"] == "python benchmarks/bench_exact.py"
    with pytest.raises(ValueError, match="already stamped"):
        gen_docs_tables.snapshot(results / "bench_exact.json", command="x", results=tmp_path)

    readme = tmp_path / "README.md"
    readme.write_text("intro\n<!-- generated: bench_exact -->\n| stale |\n<!-- end generated -->\nend\n")
    assert gen_docs_tables.update_readme(readme, results, check=True) == ["bench_exact"]
    assert "| stale |" in readme.read_text()  # check writes nothing
    assert gen_docs_tables.update_readme(readme, results) == ["bench_exact"]
    text = readme.read_text()
    assert "| brute force, K = 16 | 6 | 123 |" in text and "`python benchmarks/bench_exact.py` at commit" in text
    assert text.startswith("intro\n") and text.endswith("<!-- end generated -->\nend\n")
    assert gen_docs_tables.update_readme(readme, results, check=True) == []


def test_snapshot_can_leave_out_the_per_dataset_curves_and_the_tables_stay(tmp_path):
    results = tmp_path / "results"
    src = gen_docs_tables.RESULTS / "table_6_4_small.json"
    doc = gen_docs_tables.load_snapshot("table_6_4_small")
    kept = [
        {b: {k: v for k, v in x.items() if k != "curve"} if isinstance(x, dict) else x for b, x in r.items()}
        for r in doc["scores"]
    ]
    gen_docs_tables.snapshot(src, results=results, drop_curves=True)
    small = gen_docs_tables.load_snapshot("table_6_4_small", results)
    assert small["scores"] == kept and small["pooled"] == doc["pooled"]
    assert "per-dataset" in small["provenance"]["dropped"]
    assert {k: v for k, v in small["provenance"].items() if k != "dropped"} == doc["provenance"]
    assert (results / "table_6_4_small.json").stat().st_size < src.stat().st_size


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
    doc = gen_docs_tables.load_snapshot("table_6_4_small")
    later = {doc["pooled"][-1]["algorithm"]}
    first, second = _split_by_algorithm(doc, later)
    (results / "t.json").write_text(json.dumps(first))
    src = tmp_path / "metrics.json"
    unstamped = {k: v for k, v in second.items() if k != "provenance"}
    unstamped["datasets"] = [{**d, "seconds": 1.0} for d in unstamped["datasets"]]  # times may differ
    src.write_text(json.dumps(unstamped))
    before = (results / "t.json").read_text()

    def refused(change, match: str) -> None:
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps(change(json.loads(src.read_text()))))
        with pytest.raises(ValueError, match=match):
            gen_docs_tables.merge(bad, "t", "cmd", results)
        assert (results / "t.json").read_text() == before  # nothing written

    refused(lambda d: {**d, "seed": d["seed"] + 1}, "seed differs")
    refused(lambda d: {**d, "datasets": [{**d["datasets"][0], "scans": -1}, *d["datasets"][1:]]}, "datasets differs")
    refused(lambda d: {**d, "runs": d["runs"] + [doc["runs"][0]]}, "both hold")
    gen_docs_tables.merge(src, "t", "ogm-ppl experiment spec --algorithms x", results)
    merged = gen_docs_tables.load_snapshot("t", results)
    for key in ("scores", "pooled", "runs"):
        assert sorted(map(json.dumps, merged[key])) == sorted(map(json.dumps, doc[key]))
    prov = merged["provenance"]
    assert prov["command"] == f"{doc['provenance']['command']}; then ogm-ppl experiment spec --algorithms x"
    before_parts = doc["provenance"].get("parts", [doc["provenance"]])  # the snapshot may be a merge already
    assert prov["parts"][:-1] == before_parts and prov["parts"][-1]["command"].endswith("--algorithms x")
    assert [r[0] for r in gen_docs_tables._experiment_pooled(merged).rows] == [p["algorithm"] for p in doc["pooled"]]
    line = gen_docs_tables.provenance_line(prov)
    assert line.count(" on ") == len(before_parts) + 1 and before_parts[0]["commit"][:12] in line


def test_merge_adds_an_error_splits_algorithms(tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    doc = gen_docs_tables.load_snapshot("table_6_4_errors")
    name = sorted(doc["algorithms"])[-1]
    first = {**doc, "algorithms": {k: v for k, v in doc["algorithms"].items() if k != name}}
    (results / "e.json").write_text(json.dumps(first))
    src = tmp_path / "errors.json"
    later = {k: v for k, v in doc.items() if k not in ("provenance", "algorithms")}
    src.write_text(json.dumps({**later, "algorithms": {name: doc["algorithms"][name]}}))
    other = tmp_path / "other.json"
    other.write_text(json.dumps({**later, "cells": {"touched": 1, "untouched": 2}, "algorithms": {"x": {}}}))
    with pytest.raises(ValueError, match="cells differs"):
        gen_docs_tables.merge(other, "e", "cmd", results)
    gen_docs_tables.merge(src, "e", "python experiments/table_6_4_errors.py x", results)
    merged = gen_docs_tables.load_snapshot("e", results)
    assert merged["algorithms"] == doc["algorithms"]
    assert sorted(gen_docs_tables._error_split(merged).rows) == sorted(gen_docs_tables._error_split(doc).rows)


def test_merge_adds_an_explorations_rules_and_recomputes_its_summary(tmp_path):
    from ogm_ppl.experiment.active import summarise

    results = tmp_path / "results"
    results.mkdir()
    doc = gen_docs_tables.load_snapshot("active_full")
    methods = [r["method"] for r in doc["summary"]]
    late = set(methods[-2:])
    first = {**doc, "runs": [r for r in doc["runs"] if r["method"] not in late]}
    first["summary"] = summarise(first["runs"], methods[:-2])
    (results / "a.json").write_text(json.dumps(first))
    later = {k: v for k, v in doc.items() if k != "provenance"}
    later["runs"] = [r for r in doc["runs"] if r["method"] in late]
    later["summary"] = summarise(later["runs"], methods[-2:])  # its ratios are against its own first rule
    src = tmp_path / "metrics.json"
    src.write_text(json.dumps(later))
    before = (results / "a.json").read_text()
    bad = tmp_path / "bad.json"
    moved = [{**r, "start": [0, 0]} if i == 0 else r for i, r in enumerate(later["runs"])]
    bad.write_text(json.dumps({**later, "runs": moved}))
    with pytest.raises(ValueError, match="starts differs"):
        gen_docs_tables.merge(bad, "a", "cmd", results)
    bad.write_text(json.dumps({**later, "plans": later["plans"][:-1]}))
    with pytest.raises(ValueError, match="plans differs"):
        gen_docs_tables.merge(bad, "a", "cmd", results)
    assert (results / "a.json").read_text() == before
    gen_docs_tables.merge(src, "a", "ogm-ppl experiment active.toml --algorithms x", results)
    merged = gen_docs_tables.load_snapshot("a", results)
    assert json.dumps(merged["summary"]) == json.dumps(doc["summary"])  # ratios against the snapshot's first rule
    assert gen_docs_tables._active(merged).rows == gen_docs_tables._active(doc).rows


def test_readme_requirements_name_every_dependency_at_its_lower_bound():
    """The README's requirements line lists each of pyproject.toml's dependencies with its lower bound."""
    import tomllib

    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    text = " ".join((ROOT / "README.md").read_text().split())
    for dep in deps:
        req = dep.split(";")[0].strip()
        name, _, low = req.partition(">=")
        assert f"{name} >= {low}" in text, f"README's requirements lack {req!r}"
