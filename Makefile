# microfacet — fresh-machine entry points.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
OUT    ?= demo-output

.PHONY: setup demo test bench clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,mitsuba,dask]"
	touch $@

setup: $(VENV)/.installed

demo: setup
	$(VENV)/bin/microfacet demo -o $(OUT)

test: setup
	$(PY) -m pytest -q

bench: setup
	$(PY) benchmarks/bench_brdf.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
