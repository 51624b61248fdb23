"""A compiled prior kind of one's own stays out of numba's disk cache, in every kernel of the Gibbs call tree.

Numba's cache index of a compiled function pickles the type of every specialisation. The Gibbs kernels compile a
specialisation per prior bundle type, in the entry points (``cell_sweep.sweep``, ``patch_sweep.patch_sweep``, ...) and
in the compiled functions they call with the bundle (``_additive_sweep``, ``_candidate_sweep``, ...). A kind defined
in a module of one's own (a test module, a script, a notebook) in those indexes made every process that cannot import
that module fail to load the kernels for any prior: ``ModuleNotFoundError: No module named '...'``. Here one process
samples with a kind of a module of its own (and runs the prior contract's compiled entry points on it), and a second
process, which cannot import that module, samples with the shipped kinds from the same cache directory.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import NamedTuple

import numba
import numpy as np
import pytest

from ogm_ppl._numba_cache import cacheable_signature
from ogm_ppl.priors import BorderPatchPrior, IndependentPrior, MRFPrior, PatternFieldPrior
from ogm_ppl.sensors import GaussianRange

ROOT = Path(__file__).resolve().parents[3]
MODULE = "own_kind_for_cache_test"
BUNDLES = {"prior", "lp", "reading"}  # the parameter names of a kind's bundle in the compiled functions


class _OwnCells(NamedTuple):
    log_odds: np.ndarray


def test_only_signatures_of_the_librarys_own_types_are_cacheable():
    rng = np.random.default_rng(0)
    b = rng.integers(0, 1 << 16, 50)
    shipped = [
        IndependentPrior(0.3, 16).compiled(),
        MRFPrior((4, 4), order=2, psi=0.4, cell_prior=0.3).compiled(),
        PatternFieldPrior((6, 6), np.zeros(512)).compiled(),
        BorderPatchPrior((6, 6), b, b % 512, np.ones(50), inner=(3, 3)).compiled(),
        GaussianRange(0.6).compiled(0.5),
    ]
    array = numba.typeof(np.zeros(3, np.uint8))
    for bundle in shipped:
        assert cacheable_signature((array, numba.typeof(bundle), numba.int64)), type(bundle)

    def local():
        class Local(NamedTuple):
            x: float

        return Local(1.0)

    assert not cacheable_signature((array, numba.typeof(_OwnCells(np.zeros(4)))))  # a test module's kind
    assert not cacheable_signature((numba.typeof(local()),))  # a class that does not even pickle


def test_every_compiled_function_that_takes_a_bundle_caches_the_shipped_kinds_only():
    """``nb.njit(cache=True)`` on a function with a bundle parameter would put a kind of one's own in its index."""
    offenders = []
    for path in sorted((ROOT / "ogm_ppl").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef) and BUNDLES & {a.arg for a in node.args.args}:
                if any("cache=True" in ast.unparse(d) for d in node.decorator_list):
                    offenders.append(f"{path.relative_to(ROOT)}:{node.name}")
    assert not offenders, f"use ogm_ppl._numba_cache.njit_shipped: {offenders}"


OWN_KIND = '''
"""A compiled prior kind of one's own: independent cells under another bundle class."""
from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl.priors import IndependentPrior
from ogm_ppl.priors.compiled import register


class OwnCells(NamedTuple):
    log_odds: np.ndarray

    def sparse_patches(self):
        return False

    def patch_capacity(self, L):
        return max(1 << L if L <= 20 else 0, 2)

    def tiles_patches(self, hw, anchors):
        return False

    def factor_extent(self):
        return 0


@nb.njit
def _weights(prior, patch, cands, n, out):
    for j in range(n):
        s = 0.0
        b = 0
        for i in range(patch.shape[0]):
            c = patch[i]
            if c >= 0:
                if (cands[j] >> b) & 1:
                    s += prior.log_odds[c]
                b += 1
        out[j] = s


def _cell(prior, k, m):
    return prior.log_odds[k]


def _patch(prior, patch, m, cands, n, out, ts):
    _weights(prior, patch, cands, n, out)


def _candidates(prior, patch, m, cands, n, tag, cand_lp, out, ts):
    _weights(prior, patch, cands, n, out)


register(OwnCells, cell_log_odds=_cell, patch_prior_weights=_patch, candidate_weights=_candidates, additive=True)


class OwnPrior(IndependentPrior):
    def compiled(self):
        return OwnCells(np.ascontiguousarray(self.cell_log_odds().numpy(), dtype=np.float64))
'''

SAMPLE = """
import sys

import numpy as np
import torch

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.datasets import toy_1d
from ogm_ppl.inference._kernels.cell_sweep import prior_log_odds
from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.priors.compiled import patch_prior_batch

if sys.argv[1] == "own":
    from {module} import OwnPrior as Prior
else:
    Prior = IndependentPrior
torch.manual_seed(0)
toy = toy_1d(num_cells=12, readings=[9.0, 6.0, 7.0, 7.0])
model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(2.0), Prior(0.3, 12))
for kernel in (CellGibbs(model), PatchGibbs(model, 3)):
    kernel.setup()
    params = kernel.current_params()
    for _ in range(3):
        params = kernel.sample(params)
bundle = model.prior.compiled()
maps = np.zeros((2, 12), np.uint8)
prior_log_odds(bundle, 3, maps[0])  # the prior contract's compiled entry points
patch_prior_batch(bundle, maps, np.array([1, 3, 4], np.int64), np.arange(8, dtype=np.int64), np.empty((2, 8)))
print(type(bundle).__name__, "sampled")
"""


def _run(tmp_path: Path, kind: str, own_module_importable: bool) -> subprocess.CompletedProcess:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    path = [str(ROOT)] + ([str(tmp_path / "mods")] if own_module_importable else [])
    env["PYTHONPATH"] = os.pathsep.join(path)
    script = tmp_path / "sample.py"
    return subprocess.run(
        [sys.executable, str(script), kind], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1200
    )


def _indexes(tmp_path: Path) -> dict[str, bytes]:
    return {str(p.relative_to(tmp_path)): p.read_bytes() for p in (tmp_path / "cache").rglob("*.nbi")}


@pytest.mark.slow
def test_a_prior_kind_of_ones_own_stays_out_of_the_disk_cache(tmp_path):
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / f"{MODULE}.py").write_text(textwrap.dedent(OWN_KIND))
    (tmp_path / "sample.py").write_text(SAMPLE.format(module=MODULE))

    own = _run(tmp_path, "own", own_module_importable=True)
    assert own.returncode == 0 and "OwnCells sampled" in own.stdout, own.stderr[-3000:]
    naming = [name for name, data in _indexes(tmp_path).items() if MODULE.encode() in data]
    assert not naming, f"cache indexes naming the own kind's module: {naming}"

    shipped = _run(tmp_path, "shipped", own_module_importable=False)
    assert shipped.returncode == 0 and "IndependentCells sampled" in shipped.stdout, shipped.stderr[-3000:]
    kernels = [name for name, data in _indexes(tmp_path).items() if b"IndependentCells" in data]
    for name in ("cell_sweep.sweep", "patch_sweep.patch_sweep", "cell_sweep.prior_log_odds", "sampling.patch_prior_"):
        assert any(name in k for k in kernels), f"the shipped kind is not cached in {name}: {sorted(kernels)}"
