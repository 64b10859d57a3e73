# Two commands do everything from a fresh clone: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench venv clean

$(STAMP): pyproject.toml setup.py identify/_simkernel.c
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/shakeid demo --out demo-output

test: $(STAMP)
	$(PY) -m pytest -q

bench: $(STAMP)
	$(PY) -m pip install --quiet -e '.[bench]'
	$(PY) benchmarks/identify_speed.py
	$(PY) benchmarks/silverbox.py --data ../shared/data/silverbox/SNLS80mV.mat
	$(PY) benchmarks/stream_throughput.py
	$(PY) benchmarks/daq_throughput.py

clean:
	rm -rf $(VENV) build *.egg-info demo-output
