"""Imports point down: the inference roles sit on the compiled kernels and the model;
a role never reaches into a role above it, and the model layer never imports inference or datasets."""

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[2] / "ogm_ppl"

# rank of each inference part: imports must go to a lower rank (or stay inside the part)
# (offline patch maps condition on the MAP map; MCMC starts from a log-odds map and may propose from a guide;
# online maps run the MCMC sweeps on a growing model)
RANK = {"_kernels": 0, "tiling": 1, "log_odds": 2, "exact": 2, "patch_map": 3, "variational": 4, "mcmc": 5, "online": 6}
# below inference: may not import ogm_ppl.inference, datasets, experiment or the CLI
LOWER = (
    "models", "priors", "grid", "raycast", "scans", "sensors", "sensors_compiled", "posterior", "metrics",
    "_raycast_kernels",
)  # fmt: skip
# leaves: modules that import nothing of the library (test_leaves_import_nothing_of_the_library), so any layer may use
# them, the self-contained compiled packages included
LEAVES = ("ogm_ppl._numba_cache",)


def _imports(path: Path) -> set[str]:
    """Absolute ``ogm_ppl.*`` modules imported anywhere in the file (also inside functions)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    parts = path.relative_to(PKG.parent).with_suffix("").parts
    package = parts[:-1]  # a module's package (for __init__.py: the package itself)
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("ogm_ppl")}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                mod = ".".join(base + ((node.module,) if node.module else ()))
            else:
                mod = node.module or ""
            if mod.startswith("ogm_ppl"):
                out.add(mod)
                out |= {f"{mod}.{a.name}" for a in node.names}
    return out


def _part(module: str) -> str | None:
    bits = module.split(".")
    if len(bits) >= 3 and bits[1] == "inference" and bits[2] in RANK:
        return bits[2]
    return None


INFERENCE_FILES = sorted(
    p for p in (PKG / "inference").rglob("*.py") if p.parent != PKG / "inference" or p.stem != "__init__"
)


@pytest.mark.parametrize("path", INFERENCE_FILES, ids=lambda p: str(p.relative_to(PKG)))
def test_inference_imports_point_down(path):
    rel = path.relative_to(PKG / "inference").with_suffix("").parts
    here = rel[0]
    assert here in RANK, f"{path}: every inference module belongs to one of {sorted(RANK)}"
    for mod in _imports(path):
        there = _part(mod)
        if there is None or there == here:
            continue
        assert RANK[there] < RANK[here], f"{path.relative_to(PKG)} imports {mod}: {here} may not use {there}"


@pytest.mark.parametrize("name", LOWER)
def test_model_layer_imports_nothing_above_it(name):
    files = sorted((PKG / name).rglob("*.py")) if (PKG / name).is_dir() else [PKG / f"{name}.py"]
    for path in files:
        for mod in _imports(path):
            assert not mod.startswith(("ogm_ppl.inference", "ogm_ppl.datasets", "ogm_ppl.experiment", "ogm_ppl.cli")), (
                f"{path.relative_to(PKG)} imports {mod}"
            )


def test_delta_fitting_takes_tensors_not_datasets():
    mods = _imports(PKG / "inference" / "variational" / "delta_fit.py")
    assert not any(m.startswith("ogm_ppl.datasets") for m in mods)


def test_map_methods_sit_between_inference_and_the_experiments():
    """``methods`` may use inference, models and priors; the CLI and experiments use ``methods``; nothing
    below it imports it, and it imports neither the experiments nor the CLI."""
    for path in sorted((PKG / "methods").rglob("*.py")):
        for mod in _imports(path):
            bad = mod.startswith(("ogm_ppl.experiment", "ogm_ppl.cli"))
            assert not bad, f"{path.relative_to(PKG)} imports {mod}"
    below = [PKG / "inference", PKG / "datasets", *(PKG / n for n in LOWER)]
    for root in below:
        for path in sorted(root.rglob("*.py")) if root.is_dir() else [root.with_suffix(".py")]:
            for mod in _imports(path):
                assert not mod.startswith("ogm_ppl.methods"), f"{path.relative_to(PKG)} imports {mod}"


def test_inference_imports_no_datasets():
    for path in INFERENCE_FILES:
        up = [m for m in _imports(path) if m.startswith(("ogm_ppl.datasets", "ogm_ppl.experiment", "ogm_ppl.cli"))]
        assert not up, f"{path.relative_to(PKG)} imports {up}"


def test_guides_do_not_import_structured_guides():
    """structured_guides builds on guides, never the other way (no import cycle)."""
    mods = _imports(PKG / "inference" / "variational" / "guides.py")
    assert not any(m.startswith("ogm_ppl.inference.variational.structured_guides") for m in mods)


def test_kernels_read_priors_only_through_the_compiled_package():
    """The compiled kernels see a prior only as a bundle of ``ogm_ppl.priors.compiled``, never the rest of
    ``ogm_ppl.priors`` (the Python prior classes, tables, learning)."""
    for path in sorted((PKG / "inference" / "_kernels").rglob("*.py")):
        for mod in _imports(path):
            if mod.startswith("ogm_ppl.priors"):
                assert mod.startswith("ogm_ppl.priors.compiled"), f"{path.relative_to(PKG)} imports {mod}"


def test_leaves_import_nothing_of_the_library():
    for leaf in LEAVES:
        path = PKG.parent.joinpath(*leaf.split(".")).with_suffix(".py")
        assert not _imports(path), f"{leaf} imports {sorted(_imports(path))}"


def test_compiled_priors_are_self_contained():
    """``ogm_ppl.priors.compiled`` imports nothing of the library outside itself (but the leaves), so kernels may
    use it."""
    for path in sorted((PKG / "priors" / "compiled").rglob("*.py")):
        for mod in _imports(path):
            assert mod.startswith(("ogm_ppl.priors.compiled", *LEAVES)), f"{path.relative_to(PKG)} imports {mod}"


def test_learning_sits_above_inference_and_calibration_and_below_the_experiments():
    """``ogm_ppl.learn`` (artefacts learned from corpora) may use datasets, inference, priors and calibration;
    it imports neither the experiments nor the command line, and nothing it builds on imports it."""
    for path in sorted((PKG / "learn").rglob("*.py")):
        for mod in _imports(path):
            assert not mod.startswith(("ogm_ppl.experiment", "ogm_ppl.cli")), f"{path.relative_to(PKG)} imports {mod}"
    below = [PKG / "inference", PKG / "datasets", PKG / "priors", PKG / "calibration", *(PKG / n for n in LOWER)]
    for root in below:
        for path in sorted(root.rglob("*.py")) if root.is_dir() else [root.with_suffix(".py")]:
            for mod in _imports(path):
                assert not mod.startswith("ogm_ppl.learn"), f"{path.relative_to(PKG)} imports {mod}"


def test_compiled_sensors_are_self_contained():
    """``ogm_ppl.sensors_compiled`` imports nothing of the library outside itself (but the leaves), so kernels may use
    it."""
    for path in sorted((PKG / "sensors_compiled").rglob("*.py")):
        for mod in _imports(path):
            assert mod.startswith(("ogm_ppl.sensors_compiled", *LEAVES)), f"{path.relative_to(PKG)} imports {mod}"
