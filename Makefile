# omnijax: `make demo` and `make test` work on a fresh machine with only Python 3.11.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
OUT    ?= out

.PHONY: demo test test-slow bench clean help

help:
	@echo "make demo       create .venv, install, run the whole system on a synthetic scene with an emulated PTZ"
	@echo "make test       create .venv, install, lint (ruff), run the test suite (what CI runs)"
	@echo "make test-slow  the long statistical tests as well"
	@echo "make bench      speed benchmarks, pinned to one core"

$(STAMP): pyproject.toml
	$(PYTHON) -c 'import sys; assert sys.version_info[:2] == (3, 11), "omnijax needs Python 3.11, found " + sys.version'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/omnijax demo --out $(OUT)/demo
	@echo "open $(OUT)/demo/annotated.mp4 (the operator's view) and $(OUT)/demo/summary.json (the scores)"

# Two workers, one test file each at a time (module fixtures such as the demo run stay in one process),
# files in collection order (tests/conftest.py puts the longest first; xdist would sort them by test count).
XDIST := -n 2 --dist loadfile --no-loadscope-reorder

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -m "not slow" $(XDIST)

test-slow: $(STAMP)
	$(BIN)/python -m pytest $(XDIST)

bench: $(STAMP)
	taskset -c 0 $(BIN)/python benchmarks/bench_uncertainty.py
	taskset -c 0 $(BIN)/python benchmarks/bench_zoom.py
	taskset -c 0 $(BIN)/python benchmarks/bench_control.py
	$(BIN)/python benchmarks/bench_ptz.py
	taskset -c 0 $(BIN)/python benchmarks/bench_render.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .hypothesis
