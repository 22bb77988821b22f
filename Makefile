# deck-landing: `make demo` and `make test` each create .venv when it is missing.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test docs lint bench calibrate clean-venv

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# CPU PyTorch first, so that stable-baselines3 does not pull a CUDA build
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e ".[dev,io,docs]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/deck-landing demo

test: $(STAMP)
	$(PY) -m pytest -n 2 -q

# the documentation site in docs/_build/html; warnings (a broken reference) are errors
docs: $(STAMP)
	$(PY) -m sphinx -b html -W --keep-going docs docs/_build/html

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(PY) -m mypy estimation/

bench: $(STAMP)
	$(PY) benchmarks/bench_env_speed.py
	$(PY) benchmarks/bench_estimators.py
	$(PY) benchmarks/bench_ray_vs_pool.py

# both calibrations in the simulator; rewrites the shipped files in configs/calibration/
calibrate: $(STAMP)
	$(VENV)/bin/deck-landing calibrate --install

clean-venv:
	rm -rf $(VENV)
