# The two commands of the README: `make demo` and `make test`. Both create or reuse .venv/.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
DEMO_OUT ?= out/demo

.PHONY: demo test env extension

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e ".[bpy,test,batch]"
	touch $(STAMP)

env: $(STAMP)

demo: $(STAMP)
	$(BIN)/python scripts/demo.py $(DEMO_OUT)

test: $(STAMP)
	$(BIN)/python -m pytest -q

extension: $(STAMP)
	$(BIN)/python scripts/build_extension.py dist
