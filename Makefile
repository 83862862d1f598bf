# The two commands of the README:  `make demo`  and  `make test`.
# Both create .venv and install what they need on a fresh machine.
PYTHON ?= python3
# Python writes its bytecode caches (__pycache__/, gitignored) even where the environment
# says not to (PYTHONDONTWRITEBYTECODE=1, as on the development VM): the tests start
# hundreds of Python processes (services, the CLI, the docs' commands) and each pytest
# worker rewrites the asserts of every test module; without the caches each of them
# compiled plugcell from source again (collecting the tests: 19 s of CPU per worker
# without, 7 s with, at load 15 on the shared 2-core VM)
export PYTHONDONTWRITEBYTECODE =
VENV   ?= .venv
BIN     = $(VENV)/bin

.PHONY: demo test test-fast lint bench clean ui-bundle

OPCUA_JS = tests/opcua/js
UI_WEB   = src/plugcell/apps/ui/web

# --no-compile: pip would compile every installed module (SciPy, pandas, Playwright, …: 47 s
# of a 124 s install at load 6 on the shared 2-core VM); Python writes the caches of the
# modules a run imports when it first imports them (above)
$(BIN)/.plugcell-installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet --no-compile -e '.[dev]'
	touch $@

# node-opcua, the independent OPC UA stack the OPC UA tests run against (npm ci: exactly
# the versions of package-lock.json)
$(OPCUA_JS)/node_modules/.installed: $(OPCUA_JS)/package.json $(OPCUA_JS)/package-lock.json
	cd $(OPCUA_JS) && npm ci --no-audit --no-fund --silent
	touch $@

# three.js and esbuild for the UI's 3-D view: the bundle they make is committed
# (src/plugcell/apps/ui/static/vendor); the tests rebuild it and compare (`make ui-bundle`
# rebuilds it after a change of package.json / package-lock.json)
$(UI_WEB)/node_modules/.installed: $(UI_WEB)/package.json $(UI_WEB)/package-lock.json
	cd $(UI_WEB) && npm ci --no-audit --no-fund --silent
	touch $@

ui-bundle: $(UI_WEB)/node_modules/.installed
	cd $(UI_WEB) && npm run --silent build

demo: $(BIN)/.plugcell-installed
	$(BIN)/plugcell demo

# two pytest workers, each test file whole in one (its module fixtures and order kept; the
# docs' examples, which use fixed ports, are one file): most tests wait on service
# processes, so two workers cut the wall time even on two cores.  The files go out
# longest first (tests/conftest.py; --no-loadscope-reorder keeps that order), so that the
# two workers end together; the 30 slowest tests are listed at the end
test: $(BIN)/.plugcell-installed $(OPCUA_JS)/node_modules/.installed \
      $(UI_WEB)/node_modules/.installed
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder --durations=30

# the inner loop while developing: lint and every test not marked slow (the slow ones
# start services as processes, a browser or node-opcua); CI runs `make test`, all of them
test-fast: $(BIN)/.plugcell-installed
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/python -m pytest -q -m "not slow"

bench: $(BIN)/.plugcell-installed
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis $(OPCUA_JS)/node_modules $(UI_WEB)/node_modules
