# The two commands of the README: `make demo` and `make test`. Both create or reuse .venv/.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
DEMO_OUT ?= out/demo
# Test worker processes (pytest-xdist), each a whole test file at a time (its module fixtures are
# made once); most tests are one thread's Python and torch dispatch, so two fill two cores.
TEST_WORKERS ?= 2

.PHONY: demo test env extension

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e ".[bpy,test,batch]"
	touch $(STAMP)

env: $(STAMP)

demo: $(STAMP)
	$(BIN)/python scripts/demo.py $(DEMO_OUT)

# The whole suite with bpy 4.5 (TEST_WORKERS processes; the slowest tests listed at the end), then
# the Blender-side tests under bpy 5.x (.venv-bpy5/, Python 3.13).
test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile --durations=15
	$(BIN)/python scripts/test_blender5.py

extension: $(STAMP)
	$(BIN)/python scripts/build_extension.py dist
