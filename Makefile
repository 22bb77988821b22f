# deck-landing: `make demo` and `make test` each create .venv when it is missing.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test docs pages lint bench calibrate mutation clean-venv

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# PyTorch first, pinned (PyPI's wheel: on Linux with CUDA's libraries; a CPU build
	# installed into .venv beforehand from https://download.pytorch.org/whl/cpu is kept)
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e ".[dev,io,docs]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/deck-landing demo

# one BLAS thread a worker: two workers on two cores, each with a BLAS thread per core,
# oversubscribe the cores and wait on each other's spinning threads
test: $(STAMP)
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -n 2 --dist worksteal -q

# the documentation site in docs/_build/html; warnings (a broken reference) are errors
docs: $(STAMP)
	$(PY) -m sphinx -b html -W --keep-going docs docs/_build/html

# the README's and the docs' generated tables (ids, policies, results), from the registries
# and configs/results/*.json; tests/agents/cli/test_pages.py fails when they are stale
pages: $(STAMP)
	$(PY) -m agents.cli.pages --write

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(PY) -m mypy estimation/

# the maintained benchmarks (docs/reference/simulator.md), each at its default size
bench: $(STAMP)
	$(PY) -m benchmarks.bench_env_speed
	$(PY) -m benchmarks.bench_estimators
	$(PY) -m benchmarks.bench_mavlink_bridge
	$(PY) -m benchmarks.bench_recording_load
	$(PY) -m benchmarks.bench_corner_noise
	$(PY) -m benchmarks.bench_fused_unseen
	$(PY) -m benchmarks.bench_paper_setup
	$(PY) -m benchmarks.bench_onboard_lookahead
	$(PY) -m benchmarks.bench_decision_latency
	$(PY) -m benchmarks.bench_deck_forecast
	$(PY) -m benchmarks.fuzz_soak

# mutation testing (mutmut) of the modules in tools/mutation.yaml, each against the test files
# that import it (or the quick ones chosen among them), eight mutants at a time (many wait on
# a socket or a thread rather than compute); not part of make test. MODULES narrows it, e.g.
# make mutation MODULES='agents/io/*'; run again, it tests only the mutants of the functions
# changed since. The report: docs/reference/mutation.md
MODULES ?=
mutation: $(STAMP)
	set -f; $(PY) tools/mutation.py run $(MODULES) --workers 8
	set -f; $(PY) tools/mutation.py summary $(MODULES)

# both calibrations in the simulator; rewrites the shipped files in configs/calibration/
calibrate: $(STAMP)
	$(VENV)/bin/deck-landing calibrate --install

clean-venv:
	rm -rf $(VENV)
