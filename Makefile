# Two commands on a fresh machine: `make demo` (set-up + a few-shot run on the bundled scene) and `make test`.
VENV ?= .venv
PYTHON ?= python3
BIN := $(VENV)/bin
# The CPU build of torch must be installed before anything that depends on torch (else pip pulls CUDA wheels).
TORCH_PIN := torch==2.13.0
DEMO_SCENE := demo/lego_tiny
DEMO_OUT := outputs
# No size flags: the run is sized for the scene and the machine (README, "Run sizes"): on a CPU, for the bundled
# 100x100 scene, 800 iterations of 1024 rays on a 64^3 -> 128^3 grid.

.PHONY: demo test lint install clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q $(TORCH_PIN)
	$(BIN)/pip install -q -e ".[dev]"
	touch $@

install: $(BIN)/.installed

demo: $(BIN)/.installed
	$(BIN)/fourierf-train fourierf-vm --data $(DEMO_SCENE) --output-dir $(DEMO_OUT)
	run=$$(ls -td $(DEMO_OUT)/lego_tiny/fourierf-vm/*/ | head -n 1); \
	$(BIN)/fourierf-eval --load-config $${run}config.json --output-path $${run}eval.json

lint: $(BIN)/.installed
	$(BIN)/ruff check .

test: $(BIN)/.installed
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q -n 2

clean:
	rm -rf $(VENV) build *.egg-info
