"""``python -m gateway.worker``: one worker of ``printeps serve --workers N`` (see gateway.serve)."""

from gateway.serve import worker_main

if __name__ == "__main__":
    raise SystemExit(worker_main())
