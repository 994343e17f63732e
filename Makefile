# drake-abs: `make demo` runs the main job, `make test` the tests. Both create .venv on first use.
VENV        := .venv
PY          := $(VENV)/bin/python
STAMP       := $(VENV)/.installed
CONSTRAINTS := constraints.txt

.PHONY: demo test lint format bench docs lock clean

# Install the package with the versions the suite last passed with (constraints.txt), then
# compile and cache the numba kernels so that the first solve in a new process is fast.
$(STAMP): pyproject.toml $(CONSTRAINTS)
	@test -x $(PY) || "$$(tools/find_python312.sh)" -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip -c $(CONSTRAINTS)
	$(PY) -m pip install --quiet -e '.[dev,ray]' -c $(CONSTRAINTS)
	$(VENV)/bin/drake-abs precompile
	@touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/drake-abs demo --out results/demo

lint: $(STAMP)
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/ruff check .

test: lint
	$(PY) -m pytest tests --nbmake notebooks -q -n 2 --durations=25

# The API reference (docs/api, generated from the docstrings) and docs/*.md, as HTML in
# docs/_build/html. Warnings are errors (-W), references are checked (-n), and every page is read
# afresh (-E) so an incremental build cannot hide a warning: see docs/conf.py.
docs: $(STAMP)
	$(VENV)/bin/sphinx-build -E -W --keep-going -b html -n docs docs/_build/html

format: $(STAMP)
	$(VENV)/bin/ruff format .
	$(VENV)/bin/ruff check --fix .

bench: $(STAMP)
	$(PY) benchmarks/bench_lcp.py
	$(PY) benchmarks/bench_scenes.py
	$(PY) benchmarks/bench_policy_gradient.py --json results/bench_policy_gradient.json
	$(PY) benchmarks/bench_variance.py
	$(PY) benchmarks/bench_mpc.py
	$(PY) benchmarks/bench_drake_systems.py
	$(PY) benchmarks/bench_ray.py --json results/bench_ray.json

# Regenerate constraints.txt: upgrade to the newest versions pyproject.toml's ranges allow, run
# the whole suite, and record the versions only if it passes.
lock:
	@test -x $(PY) || "$$(tools/find_python312.sh)" -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --upgrade --upgrade-strategy eager -e '.[dev,ray]'
	$(VENV)/bin/drake-abs precompile
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/ruff check .
	$(PY) -m pytest tests --nbmake notebooks -q -n 2 --durations=25
	@echo "# The versions 'make test' last passed with (Python $$($(PY) -c 'import platform; print(platform.python_version())'), Linux x86_64)." > $(CONSTRAINTS).new
	@echo "# Regenerate with 'make lock'; pyproject.toml keeps the supported ranges." >> $(CONSTRAINTS).new
	$(PY) -m pip freeze --all --exclude-editable | grep -v '^-e ' >> $(CONSTRAINTS).new
	mv $(CONSTRAINTS).new $(CONSTRAINTS)
	@touch $(STAMP)
	@echo "wrote $(CONSTRAINTS)"

clean:
	rm -rf $(VENV) results .pytest_cache .ruff_cache
