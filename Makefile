# Two commands do everything on a fresh machine (see README):
#   make demo   set up, then run the main job on the built-in apartment
#   make test   set up, then run the test suite
PY ?= $(shell command -v python3.11 || command -v python3)
VENV ?= .venv
OUT ?= out
PYTEST_ARGS ?=
# make test runs the suite in TEST_WORKERS pytest-xdist processes, each taking whole test files (--dist loadfile)
TEST_WORKERS ?= 2

.PHONY: setup demo test clean
.DEFAULT_GOAL := demo

$(VENV)/.installed: pyproject.toml
	@$(PY) -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else "Python 3.11 is required (the bpy 4.5 wheel is built for it); set PY=/path/to/python3.11")'
	$(PY) -m venv $(VENV)
	$(VENV)/bin/python -m pip install -q --upgrade pip
	$(VENV)/bin/python -m pip install -q -e ".[test]"
	@touch $@

# PyTorch (about 5.5 GB, a minute or two) only for the tests that train a tiny detector; make demo never needs it
$(VENV)/.installed-train: $(VENV)/.installed
	$(VENV)/bin/python -m pip install -q -e ".[test,train]"
	@touch $@

setup: $(VENV)/.installed
	@bash tools/system_deps.sh $(VENV)

# demo, demo_experiment, demo_checks: the shipped specs render_jobs/demo.yaml, reloc/specs/demo_experiment.yaml
# and reloc/specs/demo_checks.yaml (a bare name is a shipped spec; a path always wins)
demo: setup
	$(VENV)/bin/synth scene build --out $(OUT)/scenes
	$(VENV)/bin/synth render demo --out $(OUT)/demo --workers 2 $(if $(wildcard $(OUT)/demo/job_state.json),--resume,)
	$(VENV)/bin/reloc experiment demo_experiment --tours $(OUT)/demo --out $(OUT)/demo/experiment
	$(VENV)/bin/reloc check demo_checks $(OUT)/demo/experiment

test: setup $(VENV)/.installed-train
	$(VENV)/bin/python -m pytest -n $(TEST_WORKERS) --dist loadfile $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
