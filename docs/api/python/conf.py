# The Python API reference (Sphinx autodoc of the pyraycut package): scripts/docs.sh builds it,
# with the package's build on PYTHONPATH and every warning an error.
project = "pyraycut"
author = "raycut developers"
copyright = "raycut developers, BSD-3-Clause"
# Plain docstrings (no NumPy or Google sections): napoleon would misread "Where: ..." lines.
extensions = ["sphinx.ext.autodoc"]
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}
html_theme = "alabaster"
html_title = "pyraycut API"
nitpicky = False
