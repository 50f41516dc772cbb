"""Helpers of the REST gateway tests (also used by tests/cli): settings in a temp folder, a real
uvicorn server in a thread, and small rule sets kept here so the tests do not depend on rules/drl."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path

from gateway.config import Settings

# Tokens of the apps with auth on (token:role:name). Here, not in conftest.py: a test that imports
# from "conftest" gets whichever conftest.py was loaded last (tests/cli has one with other tokens).
TOKENS = "tok-author:author:alice,tok-caller:caller:bob"


def make_settings(tmp: Path, **api: object) -> Settings:
    rules_dir = tmp / "rules"
    rules_dir.mkdir(parents=True, exist_ok=True)
    return Settings.model_validate(
        {"data_dir": str(tmp / "var"), "engine": {"rules_dir": str(rules_dir)}, "api": api,
         "streams": {"queries_dir": None}}  # no reception rule set here for the shipped query's binding
    )


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ServerThread:
    """A real uvicorn server on 127.0.0.1 in a thread (stopped by ``stop``)."""

    def __init__(self, app, port: int | None = None) -> None:
        import uvicorn

        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        config = uvicorn.Config(app, host="127.0.0.1", port=self.port, log_level="warning", access_log=False)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def start(self, timeout: float = 30.0) -> "ServerThread":
        self.thread.start()
        deadline = time.monotonic() + timeout
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)



TYPES = """package org.printeps.apitest;

import org.printeps.gateway.Actions;

global Actions actions;

declare Customer
    id : String
    age : int
    category : String
end
"""

RULES = """package org.printeps.apitest;

import org.printeps.gateway.Actions;

global Actions actions;

rule "Adult"
when
    $c : Customer( category == null, age >= 18 )
then
    modify($c) { setCategory("adult") };
end

rule "Greet adult"
when
    $c : Customer( category == "adult" )
then
    actions.say("pepper", "Welcome " + $c.getId() + " (MARKER)");
end
"""


def files(marker: str = "v1") -> dict[str, str]:
    """A two-file rule set whose greeting names ``marker`` (to tell versions apart by behaviour)."""
    return {"types.drl": TYPES, "greet.drl": RULES.replace("MARKER", marker)}


BROKEN = {
    "types.drl": TYPES,
    "greet.drl": "package org.printeps.apitest;\n\nrule \"Broken\"\nwhen\n    Customer( age >\nthen\nend\n",
}

FACTS = [
    {"type": "Customer", "id": "c1", "age": 34},
    {"type": "Customer", "id": "c2", "age": 7},
]
