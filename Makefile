# Two commands on a fresh machine (see README):
#   make run    installs everything, then starts the gateway with the teahouse demo
#   make test   installs everything (plus the test browser and node), then runs the whole test suite
#   make test-fast  the inner loop: the suite without the tests marked `slow` (see README)
#   make lock   refreshes requirements.lock on purpose (exact versions + hashes of every dependency)
PY      ?= python3.11
VENV    ?= .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
SUDO    := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: install system-deps browser node run serve test test-fast durations lock bench clean

# Installs come from the lock files only: exact versions with their hashes (pyproject.toml keeps
# lower bounds for people who install the package into an environment of their own).
LOCK        := requirements.lock
LOCK_NODEPS := requirements-nodeps.lock
# Nothing else of an install floats either: pip itself is pinned, and the gateway's own (editable)
# install is built with the setuptools of the lock (no build isolation, which would fetch the newest).
PIP_VERSION := 26.3

$(STAMP): pyproject.toml $(LOCK) $(LOCK_NODEPS) ros/install.sh ros/requirements-jazzy.txt $(wildcard ros/printeps_interfaces/msg/*.msg ros/printeps_interfaces/srv/*.srv)
	$(MAKE) system-deps
	[ -x $(BIN)/python ] || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q pip==$(PIP_VERSION)
	$(BIN)/pip install -q --require-hashes -r $(LOCK)
	$(BIN)/pip install -q --require-hashes --no-deps -r $(LOCK_NODEPS)
	$(BIN)/pip install -q --no-deps --no-build-isolation -e .
	bash ros/install.sh $(BIN)/python
	touch $(STAMP)

# Every install also brings the Java side up to date (a few seconds when it is): the Java helpers
# compiled from java/src, and the JVM's AOT class cache trained on them (~45 s when java/src or a
# jar changed; a process that compiles rules, a test's or a gateway's, then spends ~2 CPU-s less).
install: $(STAMP)
	$(BIN)/printeps build-java

# Build tools for the ROS 2 interface package (cmake, g++), and espeak-ng: the simulated Pepper's
# voice (and the voice tests' customers). Nothing else comes from apt at run time.
system-deps:
	@command -v cmake >/dev/null && command -v g++ >/dev/null && command -v espeak-ng >/dev/null || \
	  ($(SUDO) apt-get update -q && $(SUDO) apt-get install -y -q cmake g++ espeak-ng)

# Debian's headless chromium for the workbench's end-to-end tests (browser downloads do not work
# here): the headless-only build, as Playwright uses for headless runs (~22% less CPU a page).
browser:
	@command -v chromium-headless-shell >/dev/null || ($(SUDO) apt-get update -q && $(SUDO) apt-get install -y -q chromium-headless-shell)

# Node runs the workbench's own JavaScript tests (web/test/*.mjs, tests/workbench/test_workbench_checks.py).
node:
	@command -v node >/dev/null || ($(SUDO) apt-get update -q && $(SUDO) apt-get install -y -q nodejs)

# Refresh the lock files on purpose, after changing a dependency in pyproject.toml or
# ros/requirements-jazzy.txt. uv runs from a throwaway venv of its own, never from .venv.
LOCK_VENV ?= /tmp/printeps-lock-venv
UV_VERSION := 0.13.9
lock:
	[ -x $(LOCK_VENV)/bin/uv ] || ($(PY) -m venv $(LOCK_VENV) && $(LOCK_VENV)/bin/pip install -q uv==$(UV_VERSION))
	$(LOCK_VENV)/bin/uv pip compile pyproject.toml ros/requirements-jazzy.txt --extra embedded-db --extra test \
	  --generate-hashes --python-version 3.11 --python-platform x86_64-unknown-linux-gnu \
	  --custom-compile-command "make lock" -o $(LOCK)
	$(LOCK_VENV)/bin/uv pip compile requirements-nodeps.in --no-deps \
	  --generate-hashes --python-version 3.11 --python-platform x86_64-unknown-linux-gnu \
	  --custom-compile-command "make lock" -o $(LOCK_NODEPS)

run: install
	$(BIN)/printeps demo

serve: install
	$(BIN)/printeps serve

# Three pytest-xdist workers, each with its own JVM, SecantusDB, browser and ROS domains, one test
# file per worker at a time (--dist loadfile: a file's module fixtures are built once), the longest
# files first (tests/durations.json). On 2 cores the third fills the time the other two wait on
# processes, browsers and databases (docs/operations.md, "Where the suite's time goes").
# TEST_WORKERS=0 runs everything in one process.
TEST_WORKERS ?= 3
# Bytecode caches are written for the test runs even where the environment says not to
# (PYTHONDONTWRITEBYTECODE, common in containers): without them every pytest worker re-does
# pytest's assertion rewrite of ~275 modules and every `printeps serve` a test starts compiles the
# gateway again, ~2.4 CPU-s per pytest process measured (docs/operations.md, "Where the suite's
# time goes").
PYTEST_RUN   := env -u PYTHONDONTWRITEBYTECODE $(BIN)/pytest -n $(TEST_WORKERS) --dist loadfile

# Everything, slow tests included (what CI runs). Under CI=true a skipped test is a failure unless
# tests/skip_allowlist.txt names it with its reason.
test: install browser node
	$(PYTEST_RUN)

# The inner loop: everything but the tests marked `slow` (long soaks, cluster faults, browser stories).
test-fast: install browser node
	$(PYTEST_RUN) -m "not slow"

# Measure each test file's time (a whole run) into tests/durations.json, the order the workers get
# the files in: after adding or changing long tests.
durations: install browser node
	$(PYTEST_RUN) --record-durations

bench: install
	$(BIN)/python bench/run_all.py

clean:
	rm -rf $(VENV) var build *.egg-info
