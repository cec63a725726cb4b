# The two commands a newcomer needs: `make demo` and `make test`. Both set up the
# environment first (tools/setup_env.py: a few seconds when it is already in place).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup demo run test bench lint clean

setup:
	@$(PYTHON) tools/setup_env.py

demo: setup
	$(BIN)/slicer-ros2-bridge demo

run: setup
	$(BIN)/slicer-ros2-bridge run

test: setup
	$(BIN)/python -m pytest

bench: setup
	@for script in bench/bench_*.py; do echo "== $$script"; $(BIN)/python $$script || exit 1; done

lint: setup
	$(BIN)/python -m ruff check protocol bridge slicer_client tests bench tools
	$(BIN)/python -m mypy

clean:
	rm -rf $(VENV) build .cache .pytest_cache .hypothesis
