"""Sphinx configuration: the API reference of ogm_ppl, generated from its docstrings (``make docs``)."""

import ogm_ppl

project = "ogm_ppl"
author = "ogm_ppl contributors"
release = ogm_ppl.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",  # the reference is the docstrings
    "sphinx.ext.napoleon",  # Google/NumPy sections (Args:, Returns:)
    "sphinx.ext.mathjax",  # the ``.. math::`` and :math: of the docstrings
    "sphinx.ext.viewcode",
]
autodoc_default_options = {"members": True, "show-inheritance": True, "member-order": "bysource"}
autodoc_typehints = "description"
autodoc_mock_imports: list[str] = []
napoleon_google_docstring = True
napoleon_numpy_docstring = True
# signatures and docstrings mention library types we do not document here (torch, numpy, pyro)
nitpicky = False
exclude_patterns = ["_build"]
html_theme = "alabaster"
html_title = f"ogm_ppl {release}"
