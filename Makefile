# probreg: the two set-up commands of the README are `make demo` and `make test`.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: demo test install bench clean

$(BIN)/probreg: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(BIN)/probreg

install: $(BIN)/probreg

demo: install
	$(BIN)/probreg demo --out demo_out

test: install
	$(BIN)/python -m pytest -q --doctest-modules probreg tests

bench: install
	$(BIN)/probreg bench all

clean:
	rm -rf $(VENV) demo_out build *.egg-info
