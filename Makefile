# hg2prism: `make world1` and `make test` set everything up on a fresh clone.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: world1 world2 world3 world4 mir100 sweep-demo test test-all mazes bench bench-huge clean docs docs-all world1-bayes world1-ties

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -c constraints.txt -e '.[test]'
	touch $(STAMP)

world1: $(STAMP)
	$(BIN)/hg2prism run models/world1.toml

world2: $(STAMP)
	$(BIN)/hg2prism run models/world2.toml
	$(BIN)/hg2prism sweep models/world2.toml --param delay --values 0 1 2 3
	$(BIN)/hg2prism detect models/world2.toml --fallback robust --fallback-delta 0.1
	$(BIN)/hg2prism robust models/world2.toml --deltas 0 0.02 0.05 0.1 0.2
	$(BIN)/hg2prism sweep models/world2.toml --param inference --values bayes \
		--param decision --values map sample --out models/world2_bayes
	$(BIN)/hg2prism detect models/world2.toml --fallback robust --fallback-delta 0.2 \
		--out models/world2_replan_02
	$(BIN)/hg2prism detect models/world2.toml --fallback leader --out models/world2_replan_leader

# A 2-D sweep on Dask (a local cluster, one worker per core): world2 over delay x window.
sweep-demo: $(STAMP)
	$(BIN)/hg2prism sweep models/world2.toml --param delay --values 0 1 2 3 \
		--param window --values 1 2 --out models/world2_grid

# world3 against both observers: CUSUM (world3.toml) and Bayesian (world3_bayes.toml, same map)
world3: $(STAMP)
	$(BIN)/hg2prism run models/world3.toml
	$(BIN)/hg2prism run models/world3_bayes.toml

# world4: adaptive deception (P2's type unknown to P1: jumpy or stubborn), the adaptivity table
# (with PRISM's POMDP bounds where PRISM is installed: $PRISM or prism on the PATH)
world4: $(STAMP)
	$(BIN)/hg2prism run models/world4.toml --prism-pomdp
	$(BIN)/hg2prism sweep models/world4.toml --param weight --values 0 0.25 0.5 0.75 1 \
		--out models/world4_weight

# MIR100, a robot's attack graph (an arena world): the run, then delay x honeypots
mir100: $(STAMP)
	$(BIN)/hg2prism run models/mir100.toml
	$(BIN)/hg2prism sweep models/mir100.toml --param delay --values 0 1 2 --param traps --values 1 2 \
		--out models/mir100_sweep
	$(BIN)/hg2prism sweep models/mir100.toml --param initial_hypothesis --values 0 1 2 3 \
		--param delay --values 0 1 --deception --out models/mir100_guess

# All 200 random mazes of tests/test_mazes.py through `run` (make test runs every fifth; this
# takes about 3 minutes on two cores).
mazes: $(STAMP)
	HG2PRISM_ALL_MAZES=1 $(BIN)/python -m pytest -q -n 2 tests/test_mazes.py -k run_completes

# The numbers and tables of README.md and docs/ rendered from the showcase worlds' outputs
# (docs/cli.md, "Documentation that cannot go stale"): the fast worlds afresh, the others from
# docs/data (docs-all runs them all afresh, about five minutes; `make bench` renews
# docs/performance.md's data, bench/results.json, which make docs copies when present).
docs: world1 world3 world4 mir100 world1-bayes world1-ties
	$(BIN)/python -m hg2prism.report.docs
	cp models/world3/explorer.html docs/world3_explorer.html

docs-all: world1 world2 world3 world4 mir100 world1-bayes world1-ties
	$(BIN)/hg2prism robust models/world1.toml --out models/world1_robust
	$(BIN)/python -m hg2prism.report.docs

# world1 against the Bayesian observer, map and sample (docs/results.md)
world1-bayes: $(STAMP)
	$(BIN)/hg2prism sweep models/world1.toml --param inference --values bayes \
		--param decision --values map sample --out models/world1_bayes

# world1 with P2's ties broken the other way (docs/results.md, semantics §4)
world1-ties: $(STAMP)
	$(BIN)/hg2prism sweep models/world1.toml --param tie_break --values first last \
		--out models/world1_ties

bench: $(STAMP)
	$(BIN)/hg2prism bench --out bench

# one world of about 1e7 canonical states (about 14 GB at peak): run it alone on the machine
bench-huge: $(STAMP)
	$(BIN)/hg2prism bench --huge --out bench-huge
	mkdir -p docs/data && cp bench-huge/huge.json docs/data/bench_huge.json

# two processes, one per core; each test file stays in one, the longest first; `test` takes every
# other case of the long families of generated worlds and mazes, `test-all` every case
# (tests/conftest.py); .ci/run runs both
PYTEST = $(BIN)/python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder

test: $(STAMP)
	HG2PRISM_CASES=quick $(PYTEST)

test-all: $(STAMP)
	HG2PRISM_CASES=all $(PYTEST)

clean:
	rm -rf $(VENV) models/*/ bench/ bench-huge/
