# The two commands of the README:  `make demo`  and  `make test`.
# Both create .venv and install what they need on a fresh machine.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin

.PHONY: demo test test-fast lint bench clean

OPCUA_JS = tests/opcua/js

$(BIN)/.plugcell-installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $@

# node-opcua, the independent OPC UA stack the OPC UA tests run against (npm ci: exactly
# the versions of package-lock.json)
$(OPCUA_JS)/node_modules/.installed: $(OPCUA_JS)/package.json $(OPCUA_JS)/package-lock.json
	cd $(OPCUA_JS) && npm ci --no-audit --no-fund --silent
	touch $@

demo: $(BIN)/.plugcell-installed
	$(BIN)/plugcell demo

test: $(BIN)/.plugcell-installed $(OPCUA_JS)/node_modules/.installed
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/python -m pytest -q

# the inner loop while developing: lint and every test not marked slow (the slow ones
# start services as processes, a browser or node-opcua); CI runs `make test`, all of them
test-fast: $(BIN)/.plugcell-installed
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/python -m pytest -q -m "not slow"

bench: $(BIN)/.plugcell-installed
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis $(OPCUA_JS)/node_modules
