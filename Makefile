# r2sgen: `make demo` sets everything up and runs the whole pipeline on shipped data; `make test` runs the tests.
PYTHON ?= python3.11
VENV   ?= .venv
PY     := $(VENV)/bin/python
R2S    := $(VENV)/bin/r2s
STAMP  := $(VENV)/.installed
JOBS   ?= 2

# make corpus SOURCE=scenarionet INPUT=/data/nuscenes/scenarionet OUT=out/nuscenes [CATEGORIES=vehicles] [TIME_LIMIT=60]
# On a dask cluster: RUN_ARGS="--backend dask --scheduler tcp://HOST:8786" with OUT on a filesystem every worker sees.
SOURCE     ?=
INPUT      ?=
OUT        ?= out/corpus
CATEGORIES ?=
TIME_LIMIT ?= 60
MEMORY_LIMIT ?= 4096
RUN_ARGS   ?=

DEMO := demo-out

.PHONY: setup demo test bench corpus clean lint dreal

setup: $(STAMP)

# Pinned dependencies (requirements.lock), then the project itself in editable mode.
$(STAMP): requirements.lock requirements-nodeps.lock pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "make setup: $(PYTHON) not found (set PYTHON=...)"; exit 2; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.lock
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps -r requirements-nodeps.lock
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps -e .
	touch $(STAMP)

# The whole pipeline on data shipped in the repo: extract (a ScenarioNet excerpt) -> run -> report on the 242
# shipped nuScenes-mini keyframes, a query for a situation, then one scene end to end: program, Scenic, sampled variants, picture,
# and motion programs for the extracted excerpt (its frames carry speeds).
DEMO_FRAMES := data/nuscenes-mini-keyframes/frames.parquet
DEMO_FRAME  := scene-0103/0
# A second of the shipped Argoverse 2 log (map, speeds): its behaviour program, simulated (r2s simulate).
DEMO_LOG    := data/argoverse2-log-excerpt/frames.parquet
DEMO_LOG_ID := adcf7d18-0510-35b0-a2fa-b4cea13a6d76
DEMO_CLIP   := 100 101 102 103 104 105 106 107 108 109 110

demo: setup
	@mkdir -p $(DEMO)
	$(R2S) extract scenarionet data/nuscenes-mini-excerpt/scenarionet --categories all --out $(DEMO)/excerpt-frames.parquet
	$(R2S) run $(DEMO_FRAMES) --out $(DEMO)/programs --jobs $(JOBS)
	$(R2S) report $(DEMO)/programs --frames $(DEMO_FRAMES) --query data/patterns/queue-of-three.dsl --out $(DEMO)/report
	$(R2S) query $(DEMO_FRAMES) data/patterns/queue-of-three.dsl --out $(DEMO)/matches.parquet
	$(R2S) scene $(DEMO_FRAMES) $(DEMO_FRAME) --out $(DEMO)/scene.json
	$(R2S) synth $(DEMO)/scene.json --out $(DEMO)/scene.dsl
	$(R2S) synth $(DEMO)/scene.json --format scenic --out $(DEMO)/scene.scenic
	$(R2S) sample $(DEMO)/scene.scenic --n 5 --seed 0 --out $(DEMO)/samples
	$(R2S) render $(DEMO)/scene.json --program $(DEMO)/scene.dsl --samples 5 --seed 0 --out $(DEMO)/scene.png
	$(R2S) run $(DEMO)/excerpt-frames.parquet --motion --out $(DEMO)/motion-programs.parquet --jobs $(JOBS)
	$(R2S) scene $(DEMO)/excerpt-frames.parquet $(DEMO_FRAME) --out $(DEMO)/moving-scene.json
	$(R2S) synth $(DEMO)/moving-scene.json --motion --out $(DEMO)/moving-scene.dsl
	$(R2S) synth $(DEMO)/moving-scene.json --motion --format scenic --out $(DEMO)/moving-scene.scenic
	$(R2S) sample $(DEMO)/moving-scene.scenic --n 5 --seed 0 --out $(DEMO)/moving-samples
	$(R2S) export $(DEMO)/moving-scene.json $(DEMO)/moving-samples --to scenarionet --program $(DEMO)/moving-scene.scenic --steps 50 --out $(DEMO)/scenarionet
	$(R2S) export $(DEMO)/moving-scene.json $(DEMO)/moving-samples --to openscenario --program $(DEMO)/moving-scene.scenic --steps 50 --out $(DEMO)/openscenario
	@mkdir -p $(DEMO)/clip
	for k in $(DEMO_CLIP); do $(R2S) scene $(DEMO_LOG) $(DEMO_LOG_ID)/$$k --out $(DEMO)/clip/f$$k.json || exit 2; done
	$(R2S) synth $(foreach k,$(DEMO_CLIP),$(DEMO)/clip/f$(k).json) --behaviours --motion --lanes --format json --out $(DEMO)/clip.json
	$(R2S) simulate $(DEMO)/clip.json $(foreach k,$(DEMO_CLIP),$(DEMO)/clip/f$(k).json) --motion --lanes --n 2 --seed 0 --time-limit 60 --out $(DEMO)/simulated
	$(R2S) export $(DEMO)/simulated --scene $(DEMO_LOG_ID)-sim000 --to openscenario --out $(DEMO)/simulated-openscenario
	$(R2S) render $(foreach k,$(DEMO_CLIP),$(DEMO)/clip/f$(k).json) --simulated $(DEMO)/simulated --out $(DEMO)/clip.png
	$(R2S) run $(DEMO_LOG) --clip 2 --motion --lanes --out $(DEMO)/clip-programs --jobs $(JOBS)
	@echo
	@echo "demo done: report at $(DEMO)/report/report.html ($(DEMO)/report/report.md)"
	@echo "           one frame ($(DEMO_FRAME)): $(DEMO)/scene.dsl, scene.scenic, scene.png, samples/"
	@echo "           frames with three cars in a queue: $(DEMO)/matches.parquet (and a section of the report)"
	@echo "           motion (who is parked, who drives with whom): $(DEMO)/motion-programs.parquet, moving-scene.dsl"
	@echo "           that frame and 5 variants for simulators: $(DEMO)/scenarionet (MetaDrive), $(DEMO)/openscenario (esmini)"
	@echo "           a second of the AV2 log, its behaviours ($(DEMO)/clip.json) and 2 simulated variants: $(DEMO)/simulated"
	@echo "           the first variant for esmini: $(DEMO)/simulated-openscenario; recorded vs simulated: $(DEMO)/clip.png"
	@echo "           the whole log in clips of 2 s, a behaviour program each: $(DEMO)/clip-programs"
	@echo "next: . $(VENV)/bin/activate   (in each new shell: puts r2s and the venv's python on PATH for the README's examples)"

# Two pytest-xdist workers, each given whole test files (--dist loadfile: a module's fixtures are built once):
# about half the wall time on CI's two cores. TEST_JOBS=0 runs the suite in this one process.
TEST_JOBS ?= 2
test: setup
	$(PY) -m pytest -n $(TEST_JOBS) --dist loadfile

# dReal, the paper's solver (--solver dreal): builds IBEX 2.7.4 from IBEX_SRC into a cache directory that survives
# `make clean` (~10 min once per machine), installs requirements-dreal.lock into the venv and tells it where
# libibex is (tools/dreal.sh says how; it also names the Debian packages needed). Seconds when done already.
IBEX_SRC ?= $(wildcard ../shared/third_party/ibex-lib-2.7.4_11.tar.gz)

dreal: setup
	IBEX_SRC="$(IBEX_SRC)" VENV="$(VENV)" PYTHON="$(PYTHON)" JOBS="$(JOBS)" bash tools/dreal.sh

# Benchmarks (not tests): results in bench/results/*.json and *.md; about an hour in full, BENCH_ARGS=--quick for a
# short pass. Needs ../shared/data for the real-data parts (each script says what it skips without it).
bench: setup
	$(PY) bench/run_all.py $(BENCH_ARGS)

# A whole dataset: frames, programs (resumable: rerun the same command after a stop) and a report.
# The frames are extracted again whenever what they were extracted with changes: OUT/frames.args records the
# source, the input's absolute path, the categories (empty: r2s extract's default) and r2s's version, and is
# written only after a whole extraction. `r2s run` then recomputes only the frames whose rows changed.
EXTRACT_ARGS = $(SOURCE) $(abspath $(INPUT))$(if $(CATEGORIES), --categories $(CATEGORIES))
corpus: setup
	@test -n "$(SOURCE)" -a -n "$(INPUT)" || { echo "usage: make corpus SOURCE=scenarionet|nuscenes|argoverse2|mcap|rosbag INPUT=PATH [OUT=DIR] [CATEGORIES=all|vehicles|LIST] [JOBS=N] [TIME_LIMIT=S] [MEMORY_LIMIT=MB] [RUN_ARGS='--backend dask --scheduler tcp://HOST:8786']"; exit 2; }
	@mkdir -p $(OUT)
	@stamp="$(EXTRACT_ARGS) ($$($(R2S) --version))"; \
	if [ -d $(OUT)/frames ] && [ "$$(cat $(OUT)/frames.args 2>/dev/null)" = "$$stamp" ]; then \
		echo "corpus: $(OUT)/frames is up to date ($$stamp)"; \
	else \
		rm -f $(OUT)/frames.args && \
		echo "$(R2S) extract $(EXTRACT_ARGS) --out $(OUT)/frames --jobs $(JOBS)" && \
		$(R2S) extract $(EXTRACT_ARGS) --out $(OUT)/frames --jobs $(JOBS) && \
		printf '%s\n' "$$stamp" > $(OUT)/frames.args.tmp && mv $(OUT)/frames.args.tmp $(OUT)/frames.args; \
	fi
	$(R2S) run $(OUT)/frames --out $(OUT)/programs --jobs $(JOBS) --time-limit $(TIME_LIMIT) --memory-limit $(MEMORY_LIMIT) $(RUN_ARGS)
	$(R2S) report $(OUT)/programs --frames $(OUT)/frames --out $(OUT)/report
	@echo "corpus done: $(OUT)/programs/ (a Parquet dataset), report at $(OUT)/report/report.html"

lint: setup
	$(VENV)/bin/ruff check synth storage frames extractors pipeline bench tests

clean:
	rm -rf $(DEMO) .pytest_cache .hypothesis
