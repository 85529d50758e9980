# Two set-up commands for a fresh machine: `make demo` and `make test`.
# Each creates .venv (if missing) and installs what it needs.
VENV ?= .venv
PY := $(VENV)/bin/python
# The CPU build of torch is installed first so that pip does not pull CUDA packages.
TORCH_SPEC ?= torch==2.13.0
export MUJOCO_GL ?= egl

.PHONY: demo test lint docs install clean

$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet "$(TORCH_SPEC)"
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $@

install: $(VENV)/.installed

demo: $(VENV)/.installed
	$(VENV)/bin/handsim demo
	@echo "handsim is installed in $(VENV), not on your PATH: run 'source $(VENV)/bin/activate'" \
		"(then 'handsim --help'), or call '$(VENV)/bin/handsim'."

lint: $(VENV)/.installed
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

# The documentation, built from scratch (-E) and strictly (-W: any Sphinx warning fails).
docs: $(VENV)/.installed
	$(VENV)/bin/sphinx-build -E -W --keep-going -q -b html docs docs/_build/html

test: lint docs
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) handsim-demo .pytest_cache docs/_build
