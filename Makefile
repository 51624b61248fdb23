# Two commands do all set-up on a fresh machine: `make run` and `make test`.
# Every install goes through constraints.txt (this machine's exact versions), so both commands are
# reproducible and never pull a CUDA torch; the package's own metadata (pyproject.toml) has ranges.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
PIP := $(BIN)/python -m pip install --quiet -c constraints.txt
STAMP := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.installed-docs

.PHONY: run test check lint types docs package-check bench clean

$(BIN)/python:
	$(PY) -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml constraints.txt | $(BIN)/python
	# torch first, pinned, so that nothing pulls a multi-GB CUDA build
	$(PIP) torch
	$(PIP) -e ".[test]"
	touch $(STAMP)

$(DOCS_STAMP): $(STAMP)
	$(PIP) -e ".[test,docs]"
	touch $(DOCS_STAMP)

run: $(STAMP)
	$(BIN)/python -m ogm_ppl run --out out

# lint + types first (ruff ~1 s, mypy ~30 s from a cold cache), then the suite. The packaging test
# (minutes: a venv, torch, the dependencies) is `make package-check`, which .ci/run runs after this.
# The suite runs on 2 processes (pytest-xdist; this machine and CI have 2 cores), a test file on one of them
# (--dist loadfile): the tests of one file mostly use the same compiled kernels, which then compile on one
# process rather than on both at once. Most of a cold run (no numba cache in ogm_ppl/**/__pycache__) is
# numba compiling; a warm run takes about 4.5 min here.
test: check
	CI=1 $(BIN)/python -m pytest -q -p no:cacheprovider -n 2 --dist loadfile -m "not packaging" tests; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "pytest collected no tests: failing on purpose"; exit 1; fi; exit $$rc

check: lint types

lint: $(STAMP)
	$(BIN)/ruff check ogm_ppl tests benchmarks experiments tools docs/_ext
	$(BIN)/ruff format --check ogm_ppl tests benchmarks experiments tools docs/_ext

types: $(STAMP)
	$(BIN)/mypy

# wheel + sdist built, the wheel installed into a fresh venv that already holds torch: torch kept,
# README quick start runs from the installed wheel (tests/test_packaging.py)
package-check: $(STAMP)
	CI=1 $(BIN)/python -m pytest -q -p no:cacheprovider -m packaging tests/test_packaging.py

# the guide, results and benchmark pages (tables generated from docs/results/*.json by
# tools/gen_docs_tables.py), the notebooks (not executed) and the API reference -> docs/_build/html/index.html;
# warnings are errors, and so is a README table that differs from its snapshot
docs: $(DOCS_STAMP)
	$(BIN)/python tools/gen_docs_tables.py readme --check
	$(BIN)/sphinx-build -W --keep-going -q -b html docs docs/_build/html

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_ogm.py

# Mutation testing (tools/mutate.py, not part of `make test`): cosmic-ray mutants of the core
# modules, each run against the tests that cover it, in a copy of the tree under out/mutation/ (never this
# one). A first run took ~45 min here (164 mutants, 2 busy cores); a rerun resumes, running only mutants
# whose module or tests changed. Writes out/mutation/report.md, summary.json, survivors/*.diff.
# MODULES=metrics,sensors limits it, SITES=N samples N sites per module, ARGS="--fresh" etc. pass options.
.PHONY: mutate
mutate: $(STAMP)
	$(BIN)/python -c "import cosmic_ray" 2>/dev/null || $(PIP) cosmic-ray
	$(BIN)/python tools/mutate.py $(if $(MODULES),--modules $(MODULES)) $(if $(SITES),--per-module $(SITES)) $(ARGS)

clean:
	rm -rf $(VENV) out docs/_build build dist

# numba's on-disk caches (__pycache__/*.nbi, *.nbc) are invalidated per source file only: a compiled caller
# keeps the code of the callees it was compiled with when those change in another file. Clear them after
# editing a kernel and before timing it (CI starts from a clean clone, so it never reads a stale cache).
.PHONY: clean-numba
clean-numba:
	find ogm_ppl -name '*.nbi' -delete -o -name '*.nbc' -delete
