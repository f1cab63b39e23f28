# sonarmap: `make demo` maps a sample log, `make test` runs lint, types and tests.
# Both create .venv with everything the project needs on first use (Python 3.11+ and pip).

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
DEMO_LOG := sample_logs/office/office.mcap
DEMO_OUT := demo_out/office

.PHONY: setup demo test lint layers typecheck unit mutate bench fuzz goldens samples compare refine-time clean

$(STAMP): pyproject.toml
	$(PYTHON) -c 'import sys; sys.exit("sonarmap needs Python 3.11+") if sys.version_info < (3, 11) else None'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	# OctoMap is only the mapper benchmark's baseline; without a wheel for this Python the
	# benchmark skips its row instead of failing the set-up.
	$(BIN)/python -m pip install --quiet -e ".[bench]" || echo "octomap-python not installed: the OctoMap benchmark row will be skipped"
	# Compile the mapper's numba kernels into their on-disk cache once, here, rather than
	# in the first run (or in both test workers at once).
	$(BIN)/python -m pipeline.mapper.kernels.warm
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(BIN)/sonarmap run $(DEMO_LOG) -o $(DEMO_OUT) --force --compare-correction
	@echo "open $(DEMO_OUT)/report.html (map: $(DEMO_OUT)/map.png, nav2: $(DEMO_OUT)/map.yaml)"

lint: $(STAMP)
	$(BIN)/ruff check pipeline formats cli tests benchmarks fuzz sample_logs

# The import contract in pyproject.toml: formats/ imports neither pipeline/ nor cli/, and
# pipeline/ does not import cli/.
layers: $(STAMP)
	$(BIN)/lint-imports

typecheck: $(STAMP)
	$(BIN)/mypy

unit: $(STAMP)
	$(BIN)/python -m pytest -q -n 2

test: lint layers typecheck unit

bench: $(STAMP)
	$(BIN)/python -m benchmarks

# Thousands of mutated logs per format through every reader (about an hour on 2 cores).
fuzz: $(STAMP)
	$(BIN)/python -m fuzz.run_fuzz --examples 1000 --values 300 --side-files 40

# Mutation testing of the mapper, pose sync, scan building and nav2 maps (mutmut) on a
# seeded sample of mutants (~30 min on 2 cores; MUTATE_SAMPLE=0 runs none, `mutmut run`
# all of them, hours). Prints the score per module and the survivors (`mutmut show NAME`).
MUTATE_SAMPLE ?= 150
mutate: $(STAMP)
	$(BIN)/python -m benchmarks.mutation_sample --sample $(MUTATE_SAMPLE) --children 2

# Refresh the regression goldens on purpose (review `git diff sample_logs/goldens` after):
# the suite of sample_logs/goldens/suite.toml, run from the repository root.
goldens: $(STAMP)
	$(BIN)/sonarmap regress --suite sample_logs/goldens/suite.toml --goldens sample_logs/goldens \
	  --update --workers 2

# Regenerate the simulated sample logs (deterministic).
samples: $(STAMP)
	SONARMAP=$(BIN)/sonarmap sample_logs/regenerate.sh

# The method comparison on every log with a ground truth, OctoMap beside (README "Results"):
# the simulated office, corridor and orchard, and five real buildings (the Intel lab and the
# four Radish logs, sonar emulated from their laser scans into build/compare/), each with the
# ideal sonar (the sample logs; emulate --sonar-model ideal) and with the realistic one
# (docs/SONAR_PHYSICS.md: simulated and emulated again into build/compare/<name>-realistic).
COMPARE_DIR := build/compare
RADISH := freiburg-101 orebro fhw belgioioso
WORLDS := office corridor orchard
RADISH_LOGS := $(RADISH:%=$(COMPARE_DIR)/%.mcap)
REALISTIC := intel $(RADISH) $(WORLDS)
REALISTIC_LOGS := $(REALISTIC:%=$(COMPARE_DIR)/%-realistic.mcap)

$(COMPARE_DIR)/%.mcap: sample_logs/radish/%-corrected.log.gz | $(STAMP)
	mkdir -p $(COMPARE_DIR)
	rm -f $(COMPARE_DIR)/$*.mcap $(COMPARE_DIR)/$*.laser.* $(COMPARE_DIR)/$*.truth.*
	$(BIN)/sonarmap emulate $< -o $@ --compression zstd --sonar-model ideal

$(COMPARE_DIR)/%-realistic.mcap: sample_logs/radish/%-corrected.log.gz | $(STAMP)
	mkdir -p $(COMPARE_DIR)
	rm -f $(COMPARE_DIR)/$*-realistic.*
	$(BIN)/sonarmap emulate $< -o $@ --compression zstd --sonar-model realistic

$(COMPARE_DIR)/intel-realistic.mcap: sample_logs/intel-lab/intel-corrected.log.gz | $(STAMP)
	mkdir -p $(COMPARE_DIR)
	rm -f $(COMPARE_DIR)/intel-realistic.*
	$(BIN)/sonarmap emulate $< -o $@ --compression zstd --sonar-model realistic

# The sample logs' simulation (sample_logs/regenerate.sh) with the realistic sonar.
$(COMPARE_DIR)/%-realistic.mcap: sample_logs/worlds/%.toml | $(STAMP)
	mkdir -p $(COMPARE_DIR)
	rm -f $(COMPARE_DIR)/$*-realistic.*
	$(BIN)/sonarmap simulate $< -o $@ --compression zstd --speed 0.5 --ring-rate 5 --seed 1 \
	  --sonar-model realistic >/dev/null

compare: $(STAMP) $(RADISH_LOGS) $(REALISTIC_LOGS)
	$(BIN)/python -m benchmarks.compare_methods --figure docs/comparison.png \
	  --summary benchmarks/compare_summary.md --logs \
	  $(foreach w,$(WORLDS),sample_logs/$(w)/$(w).mcap sample_logs/$(w)/$(w).truth.yaml \
	    $(COMPARE_DIR)/$(w)-realistic.mcap $(COMPARE_DIR)/$(w)-realistic.truth.yaml) \
	  sample_logs/intel-lab/intel.mcap sample_logs/intel-lab/intel.laser.yaml \
	  $(COMPARE_DIR)/intel-realistic.mcap $(COMPARE_DIR)/intel-realistic.laser.yaml \
	  $(foreach b,$(RADISH),$(COMPARE_DIR)/$(b).mcap $(COMPARE_DIR)/$(b).laser.yaml \
	    $(COMPARE_DIR)/$(b)-realistic.mcap $(COMPARE_DIR)/$(b)-realistic.laser.yaml)
	$(BIN)/python -m benchmarks.compare_methods --drifted
	$(BIN)/python -m benchmarks.drift_variety

# The pose refinement's time target (issue 63: at most 3×): whole `sonarmap run` processes unrefined and
# refined on make compare's drifted cases and a loop floor (~5 min).
refine-time: $(STAMP)
	$(BIN)/python -m benchmarks.refine_time

clean:
	rm -rf $(VENV) demo_out build *.egg-info .pytest_cache .mypy_cache .ruff_cache
