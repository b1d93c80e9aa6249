# Development entry points. `make test` builds a venv on first use.
VENV ?= .venv
PYTHON ?= python3
STAMP := $(VENV)/.installed

# Keep ROS 2 discovery on this host.
export ROS_AUTOMATIC_DISCOVERY_RANGE = LOCALHOST

.PHONY: all venv demo demo-offline test bench clean

all: test

venv: $(STAMP)

$(STAMP): requirements.txt setup.py
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install -r requirements.txt
	$(VENV)/bin/python -m pip install -e .
	touch $@

# main job: the ROS pipeline (three nodes as processes, two-segment robot, ~20 s trajectory)
demo: $(STAMP)
	$(VENV)/bin/python -m bellow_ancf_ros.ros_demo

# the core alone: forward and inverse problems printed (no ROS)
demo-offline: $(STAMP)
	$(VENV)/bin/python -m bellow_ancf_ros.demo

test: $(STAMP)
	$(VENV)/bin/python -m pytest

bench: $(STAMP)
	$(VENV)/bin/python bench/run_bench.py
	$(VENV)/bin/python bench/fuzz_bench.py
	$(VENV)/bin/python bench/budget_bench.py

clean:
	rm -rf $(VENV)
