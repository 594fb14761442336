# One virtual environment for everything; `make demo` and `make test` create it on first use.
PY ?= python3.11
VENV := .venv
# Extras installed into .venv (CI adds ray, video, lint, docs and fast: see .ci/run).
EXTRAS ?= test
comma := ,
STAMP := $(VENV)/.installed-$(subst $(comma),-,$(EXTRAS))
# The suites run on TEST_JOBS processes (pytest-xdist), each test file in one of them (its module fixtures run
# once); the tests are mostly single-threaded: on 2 cores, 2 took a third off the default suite's time.
# TEST_JOBS=0: all in one process.
TEST_JOBS ?= 2
PYTEST := $(VENV)/bin/python -m pytest -n $(TEST_JOBS) --dist loadfile
export MUJOCO_GL ?= egl

.PHONY: setup demo test test-slow test-all test-studies wheel

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(VENV)/bin/python -m pip install -q --upgrade pip
	# torch==2.13.0 resolves to the local CPU wheel (pip's find-links); refuse a CUDA build.
	$(VENV)/bin/python -m pip install -q -e '.[$(EXTRAS)]'
	$(VENV)/bin/python -c "import torch, sys; sys.exit('CUDA build of torch installed' if torch.version.cuda else 0)"
	touch $@

# A short task-transfer demo: table on stdout, out/demo/transfer.png, out/demo/video/*.mp4.
demo: $(STAMP)
	$(VENV)/bin/cascgp transfer --quick --overwrite --out out/demo --video out/demo/video

# The default suite (about 4-9 min on 2 cores): everything but the tests marked slow.
test: $(STAMP)
	$(PYTEST)

# The long tests alone (full policy runs, multi-worker end-to-end runs, audits).
test-slow: $(STAMP)
	$(PYTEST) -m slow

# The research studies' tests (studies/, not part of the installed distribution); `-m slow` adds their end-to-end runs.
test-studies: $(STAMP)
	$(PYTEST) studies/tests

test-all: $(STAMP)
	$(PYTEST) -m ''

# The installable distribution: the wheel, in dist/.
wheel: $(STAMP)
	$(VENV)/bin/python -m pip wheel --no-deps -w dist .
