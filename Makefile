# One command sets up and runs each job; every target creates .venv when it is missing.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# the map test drives Debian's chromium (root in CI; sudo on a developer's machine); the Lua applet's test parses
# it with Debian's luac5.3 (ArduPilot's scripting is Lua 5.3, so its compiler checks the same grammar)
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# the ArduPilot Rover SITL for the firmware tests and benchmark: RETURNLINK_ARDUROVER if set, else the one shared
# beside this checkout, if any (none: the firmware tests skip and say so; .ci/run always sets it)
RETURNLINK_ARDUROVER ?= $(abspath $(wildcard ../shared/ardupilot/ardurover))
export RETURNLINK_ARDUROVER
# the PX4 rover SITL (bin/px4 and etc/) for the PX4 tests, the same way: RETURNLINK_PX4, else ../shared/px4
RETURNLINK_PX4 ?= $(abspath $(wildcard ../shared/px4))
export RETURNLINK_PX4

.PHONY: demo test test-fast bench fuzz lint venv clean

$(STAMP): pyproject.toml
	test -x /usr/bin/chromium || { $(SUDO) apt-get update && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y chromium; }
	test -x /usr/bin/luac5.3 || { $(SUDO) apt-get update && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y lua5.3; }
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	$(BIN)/returnlink dialect install
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/returnlink sim run tunnel --out out/demo

# two workers (tests/conftest.py: how the tests are grouped), then the tests that need the machine alone
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -n 2 --dist loadgroup -m "not exclusive"
	$(BIN)/python -m pytest -m exclusive

# the pure cores, their properties and the in-process protocol tests (tiers: pytestmark in each test file), under a minute
test-fast: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -m "not slow and not interop and not firmware"

bench: $(STAMP)
	@for b in benchmarks/*_bench.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

fuzz: $(STAMP)
	$(BIN)/python -m tests.fuzz_main --frames 1000000

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache .hypothesis
