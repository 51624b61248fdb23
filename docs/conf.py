"""Sphinx configuration (``make docs``): the guide, the extending page, the results and benchmark pages
(tables generated from ``docs/results/*.json`` by ``_ext/ogm_tables.py``), the notebooks (rendered as
committed, not executed) and the API reference from the docstrings."""

import sys
from pathlib import Path

import ogm_ppl

sys.path.insert(0, str(Path(__file__).resolve().parent / "_ext"))

project = "ogm_ppl"
author = "ogm_ppl contributors"
release = ogm_ppl.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",  # the reference is the docstrings
    "sphinx.ext.napoleon",  # Google/NumPy sections (Args:, Returns:)
    "sphinx.ext.mathjax",  # the ``.. math::`` and :math: of the docstrings
    "sphinx.ext.viewcode",
    "myst_nb",  # Markdown pages (MyST) and the notebooks
    "ogm_tables",  # the generated results and benchmark tables
]
autodoc_default_options = {"members": True, "show-inheritance": True, "member-order": "bysource"}
autodoc_typehints = "description"
autodoc_mock_imports: list[str] = []
napoleon_google_docstring = True
napoleon_numpy_docstring = True
# signatures and docstrings mention library types we do not document here (torch, numpy, pyro)
nitpicky = False

# the notebooks (docs/notebooks is a link to ../notebooks) are shown as committed: never executed here
nb_execution_mode = "off"
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

exclude_patterns = ["_build", "_ext", "results", "notebooks/.ipynb_checkpoints"]
html_theme = "alabaster"
html_title = f"ogm_ppl {release}"
html_theme_options = {"page_width": "1100px", "sidebar_width": "230px"}
