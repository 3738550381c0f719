# Two commands do all set-up: `make demo` and `make test` each create .venv/ and install
# what is missing, so either works as the very first command after `git clone`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# Replay output goes here; the demo log and course are the project's own.
OUT ?= out

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	@mkdir -p $(OUT)
	$(BIN)/itt-planner replay bags/typical_verona-like.mcap --course verona-like --rider typical \
		--out $(OUT)/advice.mcap --rrd $(OUT)/review.rrd --speed max

test: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q

bench: $(STAMP)
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) $(OUT) *.egg-info
