"""The REST gateway: FastAPI routers over the engine core (see ``gateway.api.app.create_app``).

Kept import-free on purpose: routers of other modules live in this package too
(``streams``, ``state``, ``workflows``) and must be importable without pulling in the app.
"""
