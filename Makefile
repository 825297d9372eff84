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

# The whole suite with bpy 4.5, then the Blender-side tests under bpy 5.x (.venv-bpy5/, Python 3.13).
test: $(STAMP)
	$(BIN)/python -m pytest -q
	$(BIN)/python scripts/test_blender5.py

extension: $(STAMP)
	$(BIN)/python scripts/build_extension.py dist
