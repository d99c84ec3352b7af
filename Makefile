# The README's two commands: `make run` (set up, then a short training run) and
# `make test` (set up, install the system packages the tests need, run the suite).
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
CONFIG ?= configs/muzero_cartpole.yaml
# `make run` is a short demonstration; drop RUN_ARGS for the preset's full budget.
RUN_ARGS ?= --set run.max_minutes=6
SYSTEM_PACKAGES := redis-server prometheus libegl1 libegl-mesa0 libgl1-mesa-dri g++
export MUJOCO_GL ?= egl

.PHONY: setup system-deps run test bench gpu-check clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[test]"
	touch $(STAMP)

# Debian packages: redis-server and prometheus are real services the tests start;
# the EGL libraries render dm_control pixels without a display; g++ builds torch.compile's CPU kernels.
system-deps:
	@missing=""; for p in $(SYSTEM_PACKAGES); do \
	  dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	fi

run: setup
	$(BIN)/wmdist train $(CONFIG) $(RUN_ARGS)

test: setup system-deps
	$(BIN)/python -m pytest -q --durations=15   # the slowest tests, to watch the 15-minute budget

bench: setup
	$(BIN)/wmdist bench all --json

gpu-check: setup  # every preset's learner and collector on CUDA vs the CPU path (skips without CUDA)
	timeout 480 $(BIN)/python -m wmdist.bench.gpu_check

clean:
	rm -rf $(VENV) runs .pytest_cache
