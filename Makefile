# Two entry points for a newcomer on a fresh machine (see README.md):
#   make demo   set everything up, then run the main job
#   make test   set everything up, then run the test suite
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
CORE := $(VENV)/.core-installed
# The environments first (core dependencies only), then the CPU build of torch, then every extra: torch must be
# installed before the extras, or pip resolves a CUDA build of several GB.
# --no-compile: Python compiles the modules it imports on first use instead of every file of every package, and
# writes the bytecode it compiled (PYTHONDONTWRITEBYTECODE is cleared for the commands below: where it is set, every
# process of the tests, each of their subprocesses and each Ray worker would compile torch's modules again, ~4 s each).
TORCH_SPEC ?= torch==2.13.0
# Every extra (planner, train, sweep) and the test tools: `pip install parallel-robot-gym` alone installs only
# what the environments need (pyproject.toml).
EXTRAS ?= all,dev

.PHONY: setup demo test lint format bench clean

setup: $(STAMP)

$(CORE): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile -e .
	touch $(CORE)

# The environments' Numba kernels compile into their on-disk cache (`python -m tests.numba_warmup`, two processes)
# while pip installs the extras, which they do not import. A warm-up that fails (see $(VENV)/warmup.log) only
# leaves its kernels to be compiled on first use; a failed install stops here.
$(STAMP): $(CORE)
	PYTHONDONTWRITEBYTECODE= $(PY) -m tests.numba_warmup > $(VENV)/warmup.log 2>&1 & warm=$$!; \
	$(PY) -m pip install --quiet --no-compile "$(TORCH_SPEC)" && \
	$(PY) -m pip install --quiet --no-compile -e ".[$(EXTRAS)]"; installed=$$?; \
	wait $$warm || echo "Numba warm-up failed (kernels compile on first use): see $(VENV)/warmup.log"; \
	exit $$installed
	touch $(STAMP)

demo: $(STAMP)
	PYTHONDONTWRITEBYTECODE= MPLBACKEND=Agg $(PY) -m experiments.demo

test: $(STAMP)
	PYTHONDONTWRITEBYTECODE= MPLBACKEND=Agg $(PY) -m pytest -n 2 --durations=15

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

format: $(STAMP)
	$(VENV)/bin/ruff format .
	$(VENV)/bin/ruff check --fix .

bench: $(STAMP)
	$(PY) -m benchmarks.bench_kinematics
	$(PY) -m benchmarks.bench_env_step
	$(PY) -m benchmarks.bench_vector_env
	$(PY) -m benchmarks.bench_sb3_ppo
	$(PY) -m pip install --quiet -e ".[bench]"  # MuJoCo, for the Reacher-v5 anchor
	$(PY) -m benchmarks.bench_family_step
	$(PY) -m benchmarks.bench_family_vector
	$(PY) -m benchmarks.bench_family_kinematics
	$(PY) -m benchmarks.bench_evaluate
	$(PY) -m benchmarks.count_lines

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache build *.egg-info
