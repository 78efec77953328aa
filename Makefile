# Quick start: `make demo` runs the main job (HIL demo), `make test` runs the test suite (on two
# pytest-xdist workers). `make test-slow` runs the checks too long for it (the fault matrices,
# every documented command; .ci/run runs both). `make paper` regenerates the
# paper's figures.
# Both create .venv (Python >= 3.10) and install the project into it when needed.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: demo paper test test-slow venv clean

# (setup.py compiles the C control cycle the campaigns step: a change of its sources installs again)
C_CYCLE := ports/c/cffi_cycle.py $(wildcard $(addprefix ports/c/,mrs_controller.[ch] mrs_monitor.[ch] mrs_cycle.[ch] \
           mrs_config.[ch] mrs_cycle_batch.[ch]))
$(STAMP): pyproject.toml setup.py $(C_CYCLE)
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/mrsteer hil demo --out out/hil-demo

paper: $(STAMP)
	$(VENV)/bin/mrsteer sim paper --out out/paper

test: $(STAMP)
	$(VENV)/bin/python -m pytest -q -n 2 --dist loadfile -m "not slow"

# The slow tests that share the machine well run on both cores; then, one at a time, those that
# need it to themselves (marker serial: realtime runs, the benchmark, the docs' blocks that run
# one of them, in the docs' order).
test-slow: $(STAMP)
	$(VENV)/bin/python -m pytest -q -n 2 --dist loadfile -m "slow and not serial" --durations=10
	$(VENV)/bin/python -m pytest -q -m "slow and serial" --durations=10

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
