"""The REST gateway (FastAPI): ``main.create_app`` over a built gateway, ``deps`` for the routes,
``routes/*`` one module per resource."""
