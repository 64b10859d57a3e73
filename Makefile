# Two commands do everything from a fresh clone: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test check bench venv clean tools

$(STAMP): pyproject.toml setup.py identify/_simkernel.c identify/_simkernel_run.h identify/_polyrows.c
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/shakeid demo --out demo-output

# Debian's docker-compose validates docker-compose.yml in the tests (no Docker engine needed), Debian's chromium
# runs the dashboard's browser tests; each installed from the Debian registry when missing and we may (root), else
# the test says how to get it.
tools:
	@command -v docker-compose >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing Debian's docker-compose (validates docker-compose.yml in the tests)"; \
	    { apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	      --no-install-recommends docker-compose >/dev/null; } \
	      || echo "note: could not install docker-compose; tests/test_deploy.py will say so"; \
	  else echo "note: docker-compose is missing; tests/test_deploy.py will say how to install it"; fi; }
	@# Debian's Chromium runs the dashboard's browser tests (tests/server/test_dashboard.py, via Playwright);
	@# they fail, saying how to install it, when it is missing
	@test -x /usr/bin/chromium || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing Debian's chromium (the dashboard's browser tests)"; \
	    { apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	      --no-install-recommends chromium >/dev/null; } \
	      || echo "note: could not install chromium; tests/server/test_dashboard.py will say so"; \
	  else echo "note: chromium is missing; tests/server/test_dashboard.py will say how to install it"; fi; }

# The whole suite: what CI runs (.ci/run).
test: $(STAMP) tools
	$(PY) -m pytest -q

# The fast tier for a change in progress: everything not marked slow (pyproject's `markers` says what slow is).
check: $(STAMP) tools
	$(PY) -m pytest -q -m "not slow"

bench: $(STAMP)
	$(PY) -m pip install --quiet -e '.[bench]'
	$(PY) benchmarks/identify_speed.py
	$(PY) benchmarks/silverbox.py
	$(PY) benchmarks/stream_throughput.py
	$(PY) benchmarks/daq_throughput.py
	$(PY) benchmarks/service_latency.py
	$(PY) benchmarks/estop_latency.py

clean:
	rm -rf $(VENV) build *.egg-info demo-output
