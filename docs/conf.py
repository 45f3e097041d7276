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
    # MathJax copied into the built site (_static/mathjax), so that the pages render their
    # mathematics offline; without it the browser fetches MathJax from a CDN
    "sphinx-mathjax-offline",
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
# The theme of the scientific Python projects' documentation (NumPy, SciPy, pandas):
# wide content, readable tables, a page table of contents, responsive below 960 px.
html_theme = "pydata_sphinx_theme"
html_static_path = ["_static"]
html_css_files = ["compass.css"]
html_title = f"compass_sparse {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": [],
}
# no left sidebar: the guide is short and the header lists its pages; the content takes
# the width (tables of options and statuses need it)
html_sidebars = {"**": []}
pygments_style = "sphinx"
smartquotes = False  # option texts quote values: keep them as typed
