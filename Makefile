# The two commands of the README: `make demo` (main job) and `make test` (tests).
export MUJOCO_GL ?= egl
export RAY_USAGE_STATS_ENABLED = 0
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup demo test test-fast bench clean

setup:
	@scripts/bootstrap.sh

demo: setup
	$(BIN)/scene-builder demo -o demo_scene

test: setup
	$(BIN)/python -m pytest -n 2 --dist loadgroup -q

test-fast: setup
	$(BIN)/python -m pytest -n 2 -q -m "not slow and not newton"

bench: setup
	$(BIN)/scene-builder bench --suite synthetic --rooms 20 --json bench.json
	$(BIN)/scene-builder bench --suite real --json real.json
	SCENE_BUILDER_MODELS=../shared/models $(BIN)/scene-builder bench --suite real --json real_det.json
	$(BIN)/python -m scene_builder.bench.report bench.json real.json real_det.json --extras > BENCHMARKS.md.tmp
	mv BENCHMARKS.md.tmp BENCHMARKS.md
	$(BIN)/python -m scene_builder.bench.readme --write

clean:
	rm -rf demo_scene .pytest_cache
