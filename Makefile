# Development entry points. `make test` builds a venv on first use.
VENV ?= .venv
PYTHON ?= python3
STAMP := $(VENV)/.installed

# Keep ROS 2 discovery on this host.
export ROS_AUTOMATIC_DISCOVERY_RANGE = LOCALHOST

.PHONY: all venv demo demo-offline demo-calibrate test bench bench-calibrate clean

all: test

venv: $(STAMP)

$(STAMP): requirements.txt setup.py
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install -r requirements.txt
	$(VENV)/bin/python -m pip install -e .
	touch $@

# main job: model vs a mismatched simulated robot, feedforward then closed loop (ROS processes, ~2 min)
demo: $(STAMP)
	$(VENV)/bin/python -m bellow_ancf_ros.ros_demo

# calibration end to end: excitation -> simulated mismatched robot seen by an offset mocap ->
# rosbag2 -> bellow-ancf calibrate -> feedforward tracking with the nominal and calibrated files
demo-calibrate: $(STAMP)
	$(VENV)/bin/python -m bellow_ancf_ros.calibration_demo

# the core alone: forward and inverse problems printed (no ROS)
demo-offline: $(STAMP)
	$(VENV)/bin/python -m bellow_ancf_ros.demo

test: $(STAMP)
	$(VENV)/bin/python -m pytest

bench: $(STAMP)
	$(VENV)/bin/python bench/run_bench.py
	$(VENV)/bin/python bench/fuzz_bench.py

# calibration of ~200 samples, one and two segments (target: under a minute)
bench-calibrate: $(STAMP)
	$(VENV)/bin/python bench/calibration_bench.py

clean:
	rm -rf $(VENV)
