# Common commands. Each target creates its own virtual environment in .venv on first use.
SHELL  := bash
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= runs/demo
# torch for the RL example (stable-baselines3): a CPU build, installed before the package so that
# pip does not resolve SB3's bare `torch` to a CUDA build of several GB. Override: make TORCH=...
TORCH  ?= torch==2.13.0
# The exact versions installed (pip constraints; docs/reproducibility.md). `make lock` remakes it
# from pyproject.toml's ranges; `make install LOCK=` installs from the ranges alone.
LOCK   ?= requirements/lock.txt
CONSTRAINTS := $(if $(LOCK),-c $(LOCK))
# Test processes (pytest-xdist): one per core, at most 4. Override: make test WORKERS=1
WORKERS ?= $(shell n=$$(nproc 2>/dev/null || echo 2); echo $$(( n < 4 ? n : 4 )))
# Each test module runs in one process: its module fixtures (episodes, sweeps) are made once.
PYTEST := $(BIN)/python -m pytest -q -n $(WORKERS) --dist loadscope
# A non-editable copy of the package for mypy (see lint).
TYPECHECK := $(VENV)/typecheck
# Files not ignored by .gitignore that differ from the last commit (nothing outside git).
GIT_STATUS := { git status --porcelain --untracked-files=all 2>/dev/null || true; }
# Top-level paths the wheel is built from (pyproject.toml [tool.setuptools]).
PKG_SOURCES := pyproject.toml README.md peg_ctrl controllers planners experiments

.PHONY: lock install demo readme-figure sysdeps sysdeps-test apt test test-slow lint bench model calibrate clean

$(STAMP): pyproject.toml $(LOCK)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet '$(TORCH)' $(CONSTRAINTS)
	$(BIN)/python -m pip install --quiet -e '.[dev]' $(CONSTRAINTS)
	touch $@

install: $(STAMP)

## demo: install, then run the main job: one autonomous episode, headless, with log, plot, video;
## then one held insertion in contact (the featured table's mpc/align, docs/demo/held_insertion.yaml)
## into $(OUT)/held_insertion, and the loop's overhead benchmark
demo: $(STAMP) sysdeps
	$(BIN)/peg-sim run --randomize --seed 0 --video --out $(OUT)
	$(BIN)/peg-sim run --config docs/demo/held_insertion.yaml --out $(OUT)/held_insertion
	$(BIN)/peg-sim bench --controller pd --task default --out $(OUT)/bench.json --repeats 3 --throughput-episodes 0

## readme-figure: the README's picture made anew: the demo's held insertion, then its frame
## halfway in beside its force profile (peg-sim replay --figure)
readme-figure: $(STAMP) sysdeps
	$(BIN)/peg-sim run --config docs/demo/held_insertion.yaml --out $(OUT)/held_insertion
	$(BIN)/peg-sim replay $(OUT)/held_insertion --figure docs/insertion.png

## sysdeps: EGL/Mesa for offscreen rendering, installed only if missing (Debian, needs root)
sysdeps:
	@ldconfig -p | grep -q 'libEGL.so.1' && ldconfig -p | grep -q 'libGL.so.1' || \
	  $(MAKE) --no-print-directory apt PKGS="libegl1 libgl1 libgl1-mesa-dri"

## sysdeps-test: also Xvfb and xdotool for the real-window teleop test
sysdeps-test: sysdeps
	@command -v Xvfb >/dev/null && command -v xdotool >/dev/null || \
	  $(MAKE) --no-print-directory apt PKGS="xvfb xdotool"

apt:
	@echo "installing $(PKGS)"
	@apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(PKGS) >/dev/null \
	  || echo "warning: could not install $(PKGS); tests that need them will skip"

## test: install, lint, type-check and run the default (fast) test suite; then check that the
## tests left no file behind in the repository (git status unchanged)
test: $(STAMP) sysdeps-test lint
	@$(GIT_STATUS) > $(VENV)/git-status.before
	$(PYTEST)
	@$(GIT_STATUS) > $(VENV)/git-status.after
	@diff -u $(VENV)/git-status.before $(VENV)/git-status.after \
	  || { echo "error: the tests created, changed or deleted the files above" >&2; exit 1; }

## test-slow: the long physics runs only
test-slow: $(STAMP)
	$(PYTEST) -m slow

## lint: ruff, then mypy on a non-editable copy. The editable install maps peg_ctrl.controllers
## (and planners, experiments) from the top-level folders with an import hook that mypy cannot
## follow, so the package is built exactly as the wheel into $(TYPECHECK)/site and checked there
## (paths in mypy's messages are the installed ones: peg_ctrl/controllers/pd.py is controllers/pd.py).
## lint-imports checks the layers (pyproject.toml [tool.importlinter], docs/architecture.md) there too.
lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	@rm -rf $(TYPECHECK) && mkdir -p $(TYPECHECK)/src
	@cp -R $(PKG_SOURCES) $(TYPECHECK)/src/
	@$(BIN)/python -m pip install --quiet --no-index --no-deps --no-build-isolation \
	  --target $(TYPECHECK)/site $(TYPECHECK)/src > $(TYPECHECK)/build.log 2>&1 \
	  || { cat $(TYPECHECK)/build.log; exit 1; }
	cd $(TYPECHECK)/site && $(CURDIR)/$(BIN)/mypy --config-file $(CURDIR)/pyproject.toml \
	  --cache-dir $(CURDIR)/.mypy_cache
	cd $(TYPECHECK)/site && $(CURDIR)/$(BIN)/lint-imports $(CURDIR)/pyproject.toml --no-cache --no-logo

bench: $(STAMP)
	$(BIN)/peg-sim bench --out $(OUT)/bench.json

model: $(STAMP)
	$(BIN)/peg-sim model --out $(OUT)/model

calibrate: $(STAMP)
	$(BIN)/peg-sim calibrate --replace-packaged

## lock: remake requirements/lock.txt: a fresh environment from pyproject.toml's ranges (no lock),
## frozen. Commit it with the studies rerun on it (docs/reproducibility.md).
lock:
	rm -rf $(VENV)-lock && $(PYTHON) -m venv $(VENV)-lock
	$(VENV)-lock/bin/python -m pip install --quiet --upgrade pip
	$(VENV)-lock/bin/python -m pip install --quiet '$(TORCH)'
	$(VENV)-lock/bin/python -m pip install --quiet -e '.[dev]'
	@mkdir -p $(dir $(LOCK))
	@{ sed -n '/^#/p' $(LOCK) 2>/dev/null; \
	  $(VENV)-lock/bin/python -m pip freeze --exclude-editable | sed -E 's/^(torch==[0-9.]+)\+cpu$$/\1/'; \
	  } > $(LOCK).tmp && mv $(LOCK).tmp $(LOCK)
	rm -rf $(VENV)-lock
	@echo "wrote $(LOCK): $$(grep -vc '^#' $(LOCK)) packages"

clean:
	rm -rf $(VENV) runs .pytest_cache .mypy_cache .ruff_cache
