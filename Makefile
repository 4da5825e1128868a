# make demo | make test | make bench | make docs — each bootstraps .venv on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
OUT    ?= out

# where the demo keeps Prefect's state; every other Prefect/Dask default is set in one place,
# flows/_env.py (the CLI and the test suite call it)
export PREFECT_HOME ?= $(CURDIR)/.prefect

.PHONY: demo test bench bench-full docs venv clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,docs]"
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p $(OUT)
	$(VENV)/bin/gcpfree prepare-reference --bbox 5.0 44.0 6.0 45.0 \
	    --out $(OUT)/reference.tif --hillshade $(OUT)/reference.png
	$(VENV)/bin/gcpfree simulate --preset tiny --seed 1 --center 5.75 44.75 \
	    --lens --date-change 0.1 --out $(OUT)/scene_tiny
	$(VENV)/bin/gcpfree pair --left $(OUT)/scene_tiny/left.tif \
	    --right $(OUT)/scene_tiny/right.tif --reference $(OUT)/scene_tiny/reference.tif \
	    --checkpoints $(OUT)/scene_tiny/truth/checkpoints.json \
	    --lidar $(OUT)/scene_tiny/truth/lidar.laz \
	    --landcover $(OUT)/scene_tiny/truth/landcover.tif --self-calibrate \
	    --out $(OUT)/pair_tiny
	mkdir -p $(OUT)/filled
	$(VENV)/bin/gcpfree fill-voids --srtm tasks/data/N44E005.hgt \
	    --dem $(OUT)/pair_tiny/dsm.tif --out $(OUT)/filled/N44E005.hgt
	@echo "demo products in $(OUT)/ (the pair's report: $(OUT)/pair_tiny/report.html)"

test: $(STAMP)
	$(PY) -m pytest -q

# the speed benchmarks (bench/perf): the quick ratios against the peers measured in the same run
# (rpcm, GDAL; xdem and CARS where bench/peers installed them), under 20 minutes on 2 cores;
# bench-full adds the long ones (a whole spot pair, the archive, hrg: hours)
bench: $(STAMP)
	$(PY) -m pip install --quiet --no-deps "rpcm>=1.4" || echo "rpcm not installed: its ratio is skipped"
	$(PY) bench/perf/run.py

bench-full: $(STAMP)
	$(PY) -m pip install --quiet --no-deps "rpcm>=1.4" || echo "rpcm not installed: its ratio is skipped"
	$(PY) bench/perf/run.py --full

# the documentation site (Sphinx + MyST, docs/) into site/; strict: a warning fails the build
docs: $(STAMP)
	$(PY) -m sphinx -W --keep-going -q -b html docs site
	@echo "documentation site: site/index.html"

clean:
	rm -rf $(OUT) .prefect .pytest_cache site
