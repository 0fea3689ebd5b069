# Two commands on a fresh machine:
#   make demo   set up, then the paper's experiment over ROS 2 (two nodes, a bag, summary, plots)
#   make test   set up, then the whole test suite (what .ci/run runs)
# Everything goes into a virtual environment of its own ($(VENV)), from the package registries.

PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
OUT    ?= results

.PHONY: demo test setup setup-test experiment payload-demo bench bench-ros results \
	readme-timings readme-bench clean

demo: $(VENV)/.runtime
	$(BIN)/rcac demo --out $(OUT)/demo

test: $(VENV)/.test
	$(BIN)/python -m rcac_ros.tools.warm
	$(BIN)/python -m pytest -q

setup: $(VENV)/.runtime
setup-test: $(VENV)/.test

experiment: $(VENV)/.runtime
	$(BIN)/rcac experiment --out $(OUT)/experiment

payload-demo: $(VENV)/.test
	$(BIN)/rcac payload-demo --out $(OUT)/payload_demo

bench: $(VENV)/.test
	$(BIN)/rcac bench core --json $(OUT)/bench.json

bench-ros: $(VENV)/.runtime
	$(BIN)/rcac bench ros --json $(OUT)/bench_ros.json

# doc/results.md and the README's results lines, from the committed doc/results/*.json
results:
	$(PYTHON) -m rcac_ros.tools.results render

# time `make demo` and `make test` in a fresh clone of HEAD (doc/results/timings.json)
readme-timings:
	$(PYTHON) -m rcac_ros.tools.results.timings --clean

# run rcac bench ros in each controller mode (doc/results/bench_ros_modes.json)
readme-bench: $(VENV)/.runtime
	$(BIN)/python -m rcac_ros.tools.results.ros_modes

$(VENV)/.runtime: requirements.txt setup.py
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	touch $(VENV)/COLCON_IGNORE  # the ROS wheels ship package.xml files colcon must not build
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r requirements.txt
	$(BIN)/python -m pip install --quiet --no-deps -e .
	touch $@

# the kernels compile (python -m rcac_ros.tools.warm) while the test requirements install
$(VENV)/.test: $(VENV)/.runtime requirements-test.txt
	$(BIN)/python -m rcac_ros.tools.warm > $(VENV)/warm.log 2>&1 & \
	$(BIN)/python -m pip install --quiet -r requirements-test.txt; status=$$?; \
	wait; cat $(VENV)/warm.log; exit $$status
	touch $@

clean:
	rm -rf $(VENV) build install log $(OUT)
