"""The rule authors' workbench: a web page served by the gateway itself (see docs/workbench.md).

``router`` (in :mod:`gateway.workbench.router`) serves the page and its bundled assets; the page
talks only to the REST API.
"""
