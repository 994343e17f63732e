# drake-abs: `make demo` runs the main job, `make test` the tests. Both create .venv on first use.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test lint format bench clean

$(STAMP): pyproject.toml
	@test -x $(PY) || "$$(tools/find_python312.sh)" -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/drake-abs demo --out results/demo

lint: $(STAMP)
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/ruff check .

test: lint
	$(PY) -m pytest tests --nbmake notebooks -q

format: $(STAMP)
	$(VENV)/bin/ruff format .
	$(VENV)/bin/ruff check --fix .

bench: $(STAMP)
	$(PY) benchmarks/bench_lcp.py
	$(PY) benchmarks/bench_scenes.py
	$(PY) benchmarks/bench_policy_gradient.py --json results/bench_policy_gradient.json
	$(PY) benchmarks/bench_variance.py
	$(PY) benchmarks/bench_mpc.py

clean:
	rm -rf $(VENV) results .pytest_cache .ruff_cache
