"""Sphinx configuration of the compass_sparse documentation.

Build: ``python3 -m sphinx -W -b html docs docs/_build/html`` (the test suite builds it
with warnings as errors into a temporary directory).  The option, status and PATH-name
tables are generated from the code by ``docs/_ext/compass_tables.py``.
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, os.path.join(HERE, "_ext"))

import compass_sparse  # noqa: E402  (after the path setup)

project = "compass_sparse"
author = "The compass_sparse developers"
copyright = "2026, " + author
version = release = compass_sparse.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "compass_tables",
]
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
autodoc_member_order = "bysource"
autodoc_typehints = "none"
autodoc_class_signature = "separated"
root_doc = "index"
exclude_patterns = ["_build"]
templates_path = []
html_theme = "alabaster"
html_static_path = []
html_title = f"compass_sparse {release}"
html_theme_options = {"description": "A sparse, large-scale MCP solver by PATH's method"}
pygments_style = "sphinx"
smartquotes = False  # option texts quote values: keep them as typed
