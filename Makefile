# Two commands on a fresh machine: `make demo` (set-up + a few-shot run on the bundled scene) and `make test`.
VENV ?= .venv
PYTHON ?= python3
BIN := $(VENV)/bin
# The CPU build of torch must be installed before anything that depends on torch (else pip pulls CUDA wheels).
TORCH_PIN := torch==2.13.0
DEMO_SCENE := demo/lego_tiny
DEMO_OUT := outputs
# Few-shot settings for the bundled 100x100 scene: batch 1024 rays, grid 64^3 -> 128^3, 800 iterations.
DEMO_FLAGS := --max-num-iterations 800 --pipeline.datamanager.rays-per-batch 1024 \
	--pipeline.model.field.n-voxels-init 262144 --pipeline.model.field.n-voxels-final 2097152

.PHONY: demo test lint install clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q $(TORCH_PIN)
	$(BIN)/pip install -q -e ".[dev]"
	touch $@

install: $(BIN)/.installed

demo: $(BIN)/.installed
	$(BIN)/fourierf-train fourierf-vm --data $(DEMO_SCENE) --output-dir $(DEMO_OUT) $(DEMO_FLAGS)
	run=$$(ls -td $(DEMO_OUT)/lego_tiny/fourierf-vm/*/ | head -n 1); \
	$(BIN)/fourierf-eval --load-config $${run}config.json --output-path $${run}eval.json

lint: $(BIN)/.installed
	$(BIN)/ruff check .

test: $(BIN)/.installed
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q -n 2

clean:
	rm -rf $(VENV) build *.egg-info
