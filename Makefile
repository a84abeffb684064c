# Common commands. Each target creates its own virtual environment in .venv on first use.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= runs/demo

.PHONY: install demo sysdeps sysdeps-test apt test test-slow lint bench model calibrate clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

install: $(STAMP)

## demo: install, then run the main job: one autonomous episode, headless, with log, plot, video
demo: $(STAMP) sysdeps
	$(BIN)/peg-sim run --randomize --seed 0 --video --out $(OUT)
	$(BIN)/peg-sim bench --controller pd --out $(OUT)/bench.json --steps 3000 --repeats 5

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

## test: install, lint, type-check and run the default (fast) test suite
test: $(STAMP) sysdeps-test lint
	$(BIN)/python -m pytest -q

## test-slow: the long physics runs only
test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/peg-sim bench --out $(OUT)/bench.json

model: $(STAMP)
	$(BIN)/peg-sim model --out $(OUT)/model

calibrate: $(STAMP)
	$(BIN)/peg-sim calibrate

clean:
	rm -rf $(VENV) runs .pytest_cache .mypy_cache .ruff_cache
