# Development entry points. `make test` builds a venv on first use.
VENV ?= .venv
PYTHON ?= python3
STAMP := $(VENV)/.installed

# Keep ROS 2 discovery on this host.
export ROS_AUTOMATIC_DISCOVERY_RANGE = LOCALHOST

.PHONY: all venv demo demo-offline demo-calibrate test bench bench-calibrate readme-speed soak clean

all: test

venv: $(STAMP)

$(STAMP): requirements.txt setup.py
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install -r requirements.txt
	$(VENV)/bin/python -m pip install -e .
	# compile the numba kernels once into their disk cache (set-up, not the first node start)
	$(VENV)/bin/python -c "from bellow_ancf_ros.core import RobotModel, load_robot, warm_up; \
	  from bellow_ancf_ros.core.dynamics import warm_up_dynamics; \
	  [(warm_up(m), warm_up_dynamics(m)) for m in \
	   (RobotModel(load_robot(n)) for n in ('one_segment', 'two_segment'))]"
	touch $@

# main job: model vs a mismatched simulated robot, feedforward then closed loop, then the loads
# phase (an unannounced payload and a push, sensed and compensated; ROS processes; 9 to 20 min
# on a quiet 2-core machine, longer on a busy one)
# the loads phase runs even when a closed-loop goal is missed; the exit status is 1 at the end
demo: $(STAMP)
	@a=0; $(VENV)/bin/python -m bellow_ancf_ros.demos.closed_loop || a=1; \
	$(VENV)/bin/python -m bellow_ancf_ros.demos.forces || a=1; \
	[ $$a -eq 0 ] || { echo "make demo: a goal was missed (see the tables above)"; exit 1; }

# calibration end to end: excitation -> simulated mismatched robot seen by an offset mocap ->
# rosbag2 -> bellow-ancf calibrate -> feedforward tracking with the nominal and calibrated files
demo-calibrate: $(STAMP)
	$(VENV)/bin/python -m bellow_ancf_ros.demos.calibration

# the core alone: forward and inverse problems printed (no ROS)
demo-offline: $(STAMP)
	$(VENV)/bin/python -m bellow_ancf_ros.demos.offline

# the tests without ROS on two workers (pytest-xdist: CPU-bound, independent), then the ROS
# tests on two workers (each its own share of the ROS domains), then the ROS tests marked
# serial alone (make demo's runs, the CPU burners, the simulation clock); fails if any part fails
test: $(STAMP)
	@$(VENV)/bin/python -m pytest -m "not ros" -n 2; a=$$?; \
	$(VENV)/bin/python -m pytest -m "ros and not serial" -n 2; b=$$?; \
	$(VENV)/bin/python -m pytest -m "ros and serial"; c=$$?; \
	[ $$a -eq 0 ] && [ $$b -eq 0 ] && [ $$c -eq 0 ] || { echo "make test: failed (without ROS: exit $$a, ROS: exit $$b, ROS serial: exit $$c)"; exit 1; }

# prints every case (median, p99, ratio to today's figure, scaling table); writes bench/speed_table.md.
# "today" = commit $(BASELINE_COMMIT) (before the real-time rewrite), run interleaved in the same
# process (a copy of it from git); without git, the figures of bench/today.json are quoted.
BASELINE_COMMIT ?= 1f2d442
bench: $(STAMP)
	@base=$$(mktemp -d); \
	if git archive $(BASELINE_COMMIT) 2>/dev/null | tar -x -C $$base 2>/dev/null; then \
	  $(VENV)/bin/python bench/run_bench.py --baseline $$base; \
	else \
	  echo "(no git copy of $(BASELINE_COMMIT): today's figures from bench/today.json)"; \
	  $(VENV)/bin/python bench/run_bench.py; \
	fi; rc=$$?; rm -rf $$base; exit $$rc
	$(VENV)/bin/python bench/fuzz_bench.py
	$(VENV)/bin/python bench/budget_bench.py
	# writes bench/redundant.json and its table in docs/performance.md
	$(VENV)/bin/python bench/redundant_bench.py --doc
	# what each hardware effect costs the closed loop (10 min on 2 busy cores): writes
	# bench/effects.json and its tables in docs/closed_loop.md
	$(VENV)/bin/python bench/effects_bench.py --doc
	# one and two segments: writes bench/stream_latency.json and its table in docs/performance.md
	$(VENV)/bin/python bench/stream_latency.py --doc
	# bench/integrator_checks.json and its table in docs/dynamics.md
	$(VENV)/bin/python bench/integrator_checks.py --doc
	$(VENV)/bin/python bench/dynamics_bench.py
	$(VENV)/bin/python bench/remedies_bench.py
	$(VENV)/bin/python bench/busy_bench.py
	# the closed loop on 100 robots of the family per segment count (about 25 min on 2 cores)
	$(VENV)/bin/python bench/family_bench.py --doc

# puts bench/speed_table.md (from the last `make bench`) into README.md between its markers
readme-speed:
	$(VENV)/bin/python bench/update_readme.py

# calibration of ~200 samples, one and two segments (target: under a minute)
bench-calibrate: $(STAMP)
	$(VENV)/bin/python bench/calibration_bench.py

# the closed loop for SOAK_MINUTES with faults injected: growth, latency, bad outputs, recovery
# (not part of `make test`)
SOAK_MINUTES ?= 10
soak: $(STAMP)
	$(VENV)/bin/python bench/soak.py --minutes $(SOAK_MINUTES)

clean:
	rm -rf $(VENV)
