# Two commands on a fresh machine (see README):
#   make run    installs everything, then starts the gateway with the teahouse demo
#   make test   installs everything (plus the test browser), then runs the test suite
PY      ?= python3.11
VENV    ?= .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
SUDO    := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: install system-deps browser run serve test bench clean

$(STAMP): pyproject.toml ros/install.sh ros/requirements-jazzy.txt $(wildcard ros/printeps_interfaces/msg/*.msg ros/printeps_interfaces/srv/*.srv)
	$(MAKE) system-deps
	[ -x $(BIN)/python ] || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e ".[embedded-db,test]"
	$(BIN)/pip install -q --no-deps python-drools-sdk==0.0.3
	bash ros/install.sh $(BIN)/python
	$(BIN)/printeps build-java
	touch $(STAMP)

install: $(STAMP)

# Build tools for the ROS 2 interface package (cmake, g++), and espeak-ng: the simulated Pepper's
# voice (and the voice tests' customers). Nothing else comes from apt at run time.
system-deps:
	@command -v cmake >/dev/null && command -v g++ >/dev/null && command -v espeak-ng >/dev/null || \
	  ($(SUDO) apt-get update -q && $(SUDO) apt-get install -y -q cmake g++ espeak-ng)

# Debian's chromium for the workbench's end-to-end tests (browser downloads do not work here).
browser:
	@command -v chromium >/dev/null || ($(SUDO) apt-get update -q && $(SUDO) apt-get install -y -q chromium)

run: install
	$(BIN)/printeps demo

serve: install
	$(BIN)/printeps serve

test: install browser
	$(BIN)/pytest

bench: install
	$(BIN)/python bench/run_all.py

clean:
	rm -rf $(VENV) var build *.egg-info
