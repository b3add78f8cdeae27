# etdmp_ros: `make demo` and `make test` build the Python environment in .venv/ themselves.
# Needs only Python >= 3.11 (with its venv module: Debian/Ubuntu package python3-venv) and make.

PYTHON      ?= python3
VENV        := .venv
VENV_PY     := $(VENV)/bin/python
PIP_VERSION := 26.3
# Stamp: the venv is (re)installed only when the lock or the package metadata changes.
STAMP       := $(VENV)/.installed
# make test PYTEST_ARGS='...' runs pytest with those arguments instead of the two steps below.
PYTEST_ARGS ?=
LETTERS_DIR ?= ../shared/data/pbdlib_2Dletters
# Upstream ROS 2 Jazzy CLI wheels and message sources (ros2 run/launch/service/topic/param, tf2_msgs):
# installed into .venv for the tests when the folder exists (tools/ros_tools.py).
ROS_TOOLS   ?= ../shared/ros
ROS_STAMP   := $(VENV)/.ros-tools

.PHONY: venv ros-tools browser test test-fast lint demo teach kinesthetic reproduce docs docs-site config bench bench-two-hosts clean distclean help
.DEFAULT_GOAL := help

help:
	@echo "make demo       headless closed-loop demo: the UR10 writes a G (SKILL=W|P|R|wipe|stir, METHOD=dmp, MOVE_GOAL=1)"
	@echo "make teach      the simulated system and the teaching page: draw a letter on http://localhost:8080"
	@echo "make kinesthetic  lead the simulated arm through a stir (teaching mode), record /joint_states;"
	@echo "                then make demo SKILL=stir DEMO_FILE=out/kinesthetic/stir_by_hand.mcap repeats it"
	@echo "make reproduce  the paper's letter experiments, offline -> out/reproduce/"
	@echo "make test       whole test suite (builds .venv/ on first use); e.g. PYTEST_ARGS='-x test'"
	@echo "make test-fast  only the unit tests, on both cores (no ROS processes, no linters)"
	@echo "make lint       flake8, pep257, mypy and the docs site with warnings as errors"
	@echo "make docs       regenerate the README pictures in docs/img/"
	@echo "make docs-site  the documentation as HTML, with the API reference -> build/docs/html/index.html"
	@echo "make config     rewrite config/*.yaml and the docs' parameter tables from etdmp_ros/ros/system.py"
	@echo "make bench      every benchmark (own .venv-bench/ with the peer libraries);"
	@echo "                one of them: make bench-core|bench-demos|bench-obstacles|bench-obstacle_volumes|bench-rest|bench-online|bench-soak|bench-sim|bench-dmp_server|bench-controller|bench-flood|bench-perception|bench-perception_restarts|bench-system|bench-kinesthetic|bench-faults"
	@echo "make bench-two-hosts  the system across two network namespaces (root): rates, latency, link cut"
	@echo "make venv       only build .venv/ (pinned requirements.txt + this package, editable)"
	@echo "make ros-tools  the ros2 CLI, launch and tf2_msgs into .venv/ from ROS_TOOLS=$(ROS_TOOLS) (make test does it)"
	@echo "make browser    headless Chromium + chromedriver for the teaching page's test (apt, as root; make test does it)"
	@echo "make clean      remove build outputs and caches; make distclean also removes .venv*/"

venv: $(STAMP)

$(VENV_PY):
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null || { \
	  echo "error: '$(PYTHON)' must be Python >= 3.11 (found: $$($(PYTHON) --version 2>&1))." >&2; \
	  echo "       Install one, or run e.g. 'make PYTHON=python3.12 $(MAKECMDGOALS)'." >&2; exit 1; }
	@$(PYTHON) -m venv $(VENV) || { rm -rf $(VENV); \
	  echo "error: '$(PYTHON) -m venv' failed. On Debian/Ubuntu: sudo apt-get install python3-venv" >&2; \
	  exit 1; }

$(STAMP): requirements.txt setup.py setup.cfg | $(VENV_PY)
	@echo "Installing pinned requirements into $(VENV)/ (about a minute the first time)..."
	$(VENV_PY) -m pip install --quiet --disable-pip-version-check "pip==$(PIP_VERSION)"
	$(VENV_PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	$(VENV_PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $@

# The ros2 CLI and launch for the tests (skipped, with the reason, when $(ROS_TOOLS) is absent).
ros-tools: $(STAMP)
	@test -f $(ROS_STAMP) -a $(ROS_STAMP) -nt requirements-ros.txt -a $(ROS_STAMP) -nt tools/ros_tools.py \
	  || $(VENV_PY) tools/ros_tools.py --from "$(ROS_TOOLS)" --stamp $(ROS_STAMP)

# Headless Chromium and its WebDriver for test/system/test_teach_page.py: Debian's chromium and
# chromium-driver, installed with apt-get when missing and this is root; otherwise (or when apt
# fails) the test skips and says why.
BROWSER_PACKAGES := chromium chromium-driver
browser:
	@if command -v chromium >/dev/null 2>&1 && command -v chromedriver >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "Installing $(BROWSER_PACKAGES) for the teaching page's browser test (apt-get)..."; \
	  { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	    $(BROWSER_PACKAGES) >/dev/null; } || \
	  echo "note: $(BROWSER_PACKAGES) not installed: test_teach_page.py will skip"; \
	else echo "note: no chromium + chromedriver and not root: test_teach_page.py will skip"; fi

# The unit suite on both cores (pytest-xdist), then the node and system suites one test at a
# time (they measure rates and gaps that tests beside them would disturb; the 15 slowest are
# listed); fails if either does.
test: $(STAMP) ros-tools browser
ifneq ($(strip $(PYTEST_ARGS)),)
	MUJOCO_GL=egl $(VENV_PY) -m pytest $(PYTEST_ARGS)
else
	status=0; \
	MUJOCO_GL=egl $(VENV_PY) -m pytest -q -n 2 test/unit || status=1; \
	MUJOCO_GL=egl $(VENV_PY) -m pytest -q --durations=15 test/nodes test/system || status=1; \
	exit $$status
endif

# The suites are folders: test/unit, test/nodes, test/system (test/conftest.py marks them).
# test-fast: the unit tests on both cores, without the checks of the whole tree (marked
# `linter`: flake8, pep257, mypy, the docs site), which `make lint` runs; make test runs all.
test-fast: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) -m pytest -q -n 2 -m 'not linter' test/unit

lint: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) -m pytest -q -m linter test/unit

# The closed loop: camera -> perception -> /generalize -> controller -> MuJoCo UR10 (out/demo/).
# MOVE_GOAL=1: the goal marker moves by 4 cm while the pen writes (online ET-DMP, --move-goal);
# with SKILL=stir the bottle moves by 2 cm and the stirrer follows it.
SKILL     ?= G
METHOD    ?= etdmp
MOVE_GOAL ?=
# DEMO_FILE=<recording.mcap> (with SKILL=stir): a stir taught by moving the arm, repeated instead.
DEMO_FILE ?=
demo: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) -m etdmp_ros.demo --skill $(SKILL) --method $(METHOD) --out out/demo \
	  $(if $(filter 1 yes true,$(MOVE_GOAL)),--move-goal) $(if $(DEMO_FILE),--demo-file $(DEMO_FILE))

# Kinesthetic teaching, simulated: ur10_sim's teaching mode leads the arm through a stir as a
# hand in freedrive would, /joint_states recorded to out/kinesthetic/stir_by_hand.mcap.
kinesthetic: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) -m etdmp_ros.demo.kinesthetic --out out/kinesthetic

# The four nodes and the teaching page (etdmp_ros/demo/teach_session.py); Ctrl-C stops them.
TEACH_PORT ?= 8080
teach: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) -m etdmp_ros.demo.teach_session --port $(TEACH_PORT)

# config/*.yaml and the parameter tables of docs/<node>.md are written from the system description.
config: $(STAMP)
	$(VENV_PY) -m etdmp_ros.ros.config_files

# The paper's letter experiments, offline (Figs. 5, 7-8, 13 and metrics.json in out/reproduce/).
reproduce: $(STAMP)
	@test -d "$(LETTERS_DIR)" || { echo "error: $(LETTERS_DIR) not found (the paper's letter data set sits beside the repository)" >&2; exit 1; }
	$(VENV)/bin/etdmp reproduce --letters-dir "$(LETTERS_DIR)" \
	  --table "$(LETTERS_DIR)/table2.json" --out out/reproduce

# README pictures: the paper reproduction's figures and one built-in generalization.
docs: reproduce
	mkdir -p docs/img
	cp out/reproduce/fig5_generalization.png out/reproduce/fig7_8_obstacles.png \
	  out/reproduce/fig13_nrmse.png docs/img/
	$(VENV)/bin/etdmp generalize --skill G --start -6 4 --goal 0 0 --obstacle -7.6 -4.4 \
	  --plot docs/img/generalize_G.png
	MUJOCO_GL=egl $(VENV_PY) tools/render_scene.py
	$(VENV_PY) tools/draw_layers.py

# The documentation site: docs/*.md (MyST) and the API reference from the docstrings (docs/conf.py;
# rosdoc2.yaml points docs.ros.org's builder at the same files). Warnings are errors, as in the test.
docs-site: $(STAMP)
	$(VENV_PY) -m sphinx -W --keep-going -q -b html docs build/docs/html
	@echo "open build/docs/html/index.html"

# The benchmark's own environment: the project's pins plus the peer libraries it compares
# against (movement-primitives, pydmps), which never enter .venv/.
BENCH_VENV  := .venv-bench
BENCH_STAMP := $(BENCH_VENV)/.installed
BENCH_REQ   := test/benchmarks/requirements-bench.txt
BENCH_ARGS  ?=

$(BENCH_STAMP): requirements.txt $(BENCH_REQ) setup.py setup.cfg
	$(PYTHON) -m venv $(BENCH_VENV)
	$(BENCH_VENV)/bin/python -m pip install --quiet --disable-pip-version-check "pip==$(PIP_VERSION)"
	$(BENCH_VENV)/bin/python -m pip install --quiet --disable-pip-version-check \
	  -r requirements.txt -r $(BENCH_REQ)
	$(BENCH_VENV)/bin/python -m pip install --quiet --disable-pip-version-check \
	  --no-deps --no-build-isolation -e .
	@touch $@

BENCHMARKS := core obstacles obstacle_volumes sim dmp_server controller perception system

bench: $(addprefix bench-,$(BENCHMARKS))

# Record a stir by hand, learn it, repeat it (needs no peer library).
bench-kinesthetic: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) test/benchmarks/bench_kinesthetic.py $(BENCH_ARGS)

# One online update (the goal followed), the core alone and end to end in the closed loop; writes
# docs/online_goal.md's tables (needs no peer library).
bench-online: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) test/benchmarks/bench_online.py $(BENCH_ARGS)

# /generalize hammered while the arm tracks a long path, junk on its input; writes
# docs/reliability.md's soak table (needs no peer library).
bench-soak: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) test/benchmarks/bench_soak.py $(BENCH_ARGS)

# Obstacles with a size, ROS side: radii measured, contacts found, the arm checked; writes the
# tables of docs/perception.md, ur10_sim.md and dmp_server.md (needs no peer library).
bench-obstacle_volumes: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) test/benchmarks/bench_obstacle_volumes.py $(BENCH_ARGS)

# Every plan at rest at its goal past tau, on recordings that start or end moving
# (docs/design.md, "Coming to rest"; needs no peer library). BENCH_ARGS="--before REV" adds the
# code of git REV beside it.
bench-rest: $(STAMP)
	$(VENV_PY) test/benchmarks/bench_rest.py $(BENCH_ARGS)

# The demo of every built-in skill with ET-DMP and the plain DMP; writes docs/demo.md's table and
# the README's results (needs no peer library).
bench-demos: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) test/benchmarks/bench_demos.py $(BENCH_ARGS)

# The closed loop as `make demo` runs it, idle and next to a busy core (needs no peer library).
bench-system: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) test/benchmarks/bench_system.py $(BENCH_ARGS)

# Two hosts on one machine (network namespaces, as root; docs/two_hosts.md): G across a UDP link
# against one host, and the link cut mid-letter (needs no peer library; not in `make bench`).
bench-two-hosts: $(STAMP)
	MUJOCO_GL=egl $(VENV_PY) test/benchmarks/bench_two_hosts.py $(BENCH_ARGS)

# Restarts of ros2 launch in one domain after a crash, each node killed (the ros2 CLI;
# docs/reliability.md; about 50 minutes, not in `make bench`).
bench-faults: $(STAMP) ros-tools
	MUJOCO_GL=egl $(VENV_PY) test/benchmarks/bench_faults.py $(BENCH_ARGS)

# The nodes' own benchmarks run in the nodes' environment (with tf2_msgs: ur10_sim publishes /tf).
bench-sim bench-dmp_server bench-perception bench-perception_restarts bench-flood: bench-%: $(STAMP) ros-tools
	MUJOCO_GL=egl $(VENV_PY) test/benchmarks/bench_$*.py $(BENCH_ARGS)

# make bench-core, bench-obstacles, bench-controller: beside their peer libraries
bench-%: $(BENCH_STAMP)
	MUJOCO_GL=egl $(BENCH_VENV)/bin/python test/benchmarks/bench_$*.py $(BENCH_ARGS)

clean:
	rm -rf out build install log .pytest_cache .mypy_cache *.egg-info
	find . -path ./.git -prune -o -path './.venv*' -prune -o \
	  \( -name __pycache__ -o -name '*.nbi' -o -name '*.nbc' \) -print0 | xargs -0 rm -rf

distclean: clean
	rm -rf $(VENV) .venv-*
