# The two commands a newcomer needs: `make demo` and `make test`. Both set up the
# environment first (tools/setup_env.py: a few seconds when it is already in place).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup demo run test test-fast coverage coverage-native bench fuzz lint clean wheel client-wheel

setup:
	@$(PYTHON) tools/setup_env.py

# DEMO_ARGS: options of `slicer-ros2-bridge demo`, e.g. DEMO_ARGS="--port 19000".
DEMO_ARGS ?=
demo: setup
	$(BIN)/slicer-ros2-bridge demo $(DEMO_ARGS)

run: setup
	$(BIN)/slicer-ros2-bridge run

test: setup
	$(BIN)/python -m pytest

# The unit and in-process tiers only (no daemon, ROS peer or build is started): for working
# in a loop. `make test` is the whole suite, as CI runs it.
test-fast: setup
	$(BIN)/python -m pytest -m "not integration"

# The suite under coverage (the daemons and scripts it starts included, see
# [tool.coverage.run] in pyproject.toml), then one report of bridge/ and slicer_client/.
# PYTEST_ARGS: what to run instead of the whole suite, e.g. PYTEST_ARGS="tests/bridge -x".
# Data in .cache/coverage; the report is printed even when a test fails (make still fails).
PYTEST_ARGS ?=
coverage: setup
	$(BIN)/python -m coverage erase
	@mkdir -p .cache/coverage
	$(BIN)/python -m coverage run -m pytest $(PYTEST_ARGS); status=$$?; \
		$(BIN)/python -m coverage combine --quiet && $(BIN)/python -m coverage report \
		&& exit $$status

# The compiled modules' .pyx lines, which `coverage` cannot see: their tests against a build
# with Cython's line tracing (built once per source digest in .cache/native-coverage/), under
# Cython's coverage plugin. PYTEST_ARGS: other tests to run against it.
coverage-native: setup
	$(BIN)/python tools/native_coverage.py $(PYTEST_ARGS)

bench: setup
	@for script in bench/bench_*.py; do echo "== $$script"; $(BIN)/python $$script || exit 1; done

# Coverage-guided fuzzing of the decoder and the command schema, FUZZ_SECONDS long
# (installs the pinned `fuzz` extra first). Findings land in .cache/fuzz/crash-*.
FUZZ_SECONDS ?= 300
fuzz: setup
	@$(BIN)/python -m pip install --quiet --disable-pip-version-check -e ".[fuzz]" \
		> .cache/pip-fuzz.log 2>&1 || { cat .cache/pip-fuzz.log; exit 1; }
	@mkdir -p .cache/fuzz/corpus
	cd .cache/fuzz && ../../$(BIN)/python ../../bench/fuzz_decoder.py \
		-max_total_time=$(FUZZ_SECONDS) corpus

# The daemon's wheel (protocol, bridge, slicer_client; pinned ROS 2 wheels as dependencies)
# and the client's own (slicer_client and protocol, numpy only, Python 3.9+), into dist/.
wheel: setup
	$(BIN)/python -m pip wheel --no-deps --wheel-dir dist .

# The client's wheel needs Python and pip only: no ROS set-up first.
client-wheel:
	$(PYTHON) tools/build_client_wheel.py --out dist

lint: setup
	$(BIN)/python -m ruff check protocol bridge slicer_client tests bench tools
	$(BIN)/python -m mypy

clean:
	rm -rf $(VENV) build dist .cache .pytest_cache .hypothesis bridge/tf/_compiled_store.c \
		bridge/ros/_rcl_reader.c bridge/ros/_rcl_reader.*.so \
		bridge/tf/_compiled_store.*.so bridge/core/_native_stream.c bridge/core/_native_stream.*.so
