# Two commands from a fresh clone: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test install bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

# torch and torchvision first, as a matching pair from the registry, so that
# resolving the project's other dependencies never replaces torch.
$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install -q torch torchvision
	$(BIN)/python -m pip install -q -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/frontiernet demo --out outputs/demo

# One pytest worker per core (pytest-xdist): on a 2-core machine `make test` took 512 s against 858 s
# for one process (0.60x; 2026-12-02, each beside a niced benchmark); many tests wait on subprocesses
# and worker pools. `pytest` alone still runs it in one process.
test: $(STAMP)
	$(BIN)/python -m pytest -q -n auto

bench: $(STAMP)
	$(BIN)/frontiernet bench render

clean:
	rm -rf $(VENV) outputs
