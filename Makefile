# One virtual environment for everything; `make demo` and `make test` create it on first use.
PY ?= python3.11
VENV := .venv
STAMP := $(VENV)/.installed-stamp
export MUJOCO_GL ?= egl

.PHONY: setup demo test test-all bench

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(VENV)/bin/python -m pip install -q --upgrade pip
	# torch==2.13.0 resolves to the local CPU wheel (pip's find-links); refuse a CUDA build.
	$(VENV)/bin/python -m pip install -q -e '.[test]'
	$(VENV)/bin/python -c "import torch, sys; sys.exit('CUDA build of torch installed' if torch.version.cuda else 0)"
	touch $@

demo: $(STAMP)
	$(VENV)/bin/python -m scripts.task_transfer --quick --overwrite --out out/demo --video out/demo/video

test: $(STAMP)
	$(VENV)/bin/python -m pytest

test-all: $(STAMP)
	$(VENV)/bin/python -m pytest -m ''
