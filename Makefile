# prt_relight: build / test / packaging entry points (GNU make, bash).
#
#   make setup   apt runtime libs for headless bpy + .venv from requirements.txt
#   make wheels  download the embreex wheels named in blender_manifest.toml
#   make build   validate + build per-platform extension zips into dist/
#   make test    run the test suite (PYTEST_ARGS="-k foo -x" to pass options)
#   make test-core  the Blender-free tests of core/ (tests/core, under a minute)
#   make lint    the house rules (tools/lint.py: file and folder sizes, private names, cycles, core free of bpy)
#   make docs    write docs/architecture.md's module map from the tree (tools/architecture.py)
#   make shaders write shaders/lib/constants.glsl from the Python constants (tools/glsl_constants.py)
#   make demo    render the demo into out/demo
#   make bench   run the precompute benchmark
#   make bench-scale  production scale: 25k-500k vertices (time, memory, storage, AUTO)
#   make bench-dynamic  shadow fields: precompute/storage per detail, frames with 1/4/16 dynamic objects
#   make bench-bounces  bounced light: every method against Cycles with bounces and direct, F12 both ways
#   make bench-lamps  frame cost per lamp: 0 to 64 spots in rows, every one with its shadow
#   make bench-frames  relit frames of every method against Workbench, with the profile
#   make bench-gpu  ms per frame of every method beside Workbench and EEVEE at 1920x1080 on the GPU
#   make fuzz    the scene fuzzer: FUZZ_N random scenes (default 500) from seed FUZZ_SEED0 (default 0), each precomputed and rendered (tests/fuzz/run.py)
#   make report  speed/error report of every method into out/report
#   make clean   remove dist/, out/, caches   (make distclean: also .venv, wheels/)

SHELL := bash
.SHELLFLAGS := -euo pipefail -c
.DEFAULT_GOAL := test
.DELETE_ON_ERROR:
MAKEFLAGS += --no-builtin-rules

VENV        := .venv
VENV_PY     := $(VENV)/bin/python
SETUP_STAMP := $(VENV)/.setup-stamp
DIST        := dist
PYTEST_ARGS ?=

# Blender's extension command line tool ships inside the bpy wheel.
BLENDER_EXT = $(firstword $(wildcard $(VENV)/lib/python3.11/site-packages/bpy/*/scripts/addons_core/bl_pkg/cli/blender_ext.py))

# Shared libraries the bpy wheel links against / dlopens (X11 client libs,
# libGL/GLVND) plus Mesa EGL + GBM for headless GPU-module use.
APT_PACKAGES := \
	libx11-6 libxext6 libxrender1 libxfixes3 libxi6 libxxf86vm1 libxkbcommon0 \
	libsm6 libice6 libxt6 libgl1 libopengl0 libglx-mesa0 \
	libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1

.PHONY: setup apt venv wheels validate build test test-core lint docs shaders demo bench bench-scale bench-dynamic bench-lamps bench-frames bench-gpu bench-methods bench-bounces fuzz report clean distclean

setup: apt venv

# Idempotent: only calls apt-get when a package is actually missing.
apt:
	@if ! command -v dpkg >/dev/null 2>&1; then \
	  echo "apt: no dpkg (not Debian/Ubuntu); make sure these are installed: $(APT_PACKAGES)"; exit 0; \
	fi; \
	missing=(); \
	for p in $(APT_PACKAGES); do \
	  [ "$$(dpkg-query -W -f='$${Status}' "$$p" 2>/dev/null || true)" = "install ok installed" ] || missing+=("$$p"); \
	done; \
	if [ $${#missing[@]} -eq 0 ]; then exit 0; fi; \
	echo "apt: installing $${missing[*]}"; \
	SUDO=; if [ "$$(id -u)" -ne 0 ]; then SUDO=sudo; fi; \
	$$SUDO apt-get update -qq; \
	$$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$${missing[@]}"

venv: $(SETUP_STAMP)

$(SETUP_STAMP): requirements.txt
	@if command -v python3.11 >/dev/null 2>&1 && python3.11 -c '' >/dev/null 2>&1; then \
	  py=python3.11; \
	elif python3 -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then \
	  py=python3; \
	else \
	  echo "setup: Python 3.11 is required (bpy==5.0.1 is cp311 only)" >&2; exit 1; \
	fi; \
	if [ ! -x $(VENV_PY) ] || ! $(VENV_PY) -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then \
	  rm -rf $(VENV); \
	  echo "setup: creating $(VENV) with $$py"; \
	  $$py -m venv $(VENV); \
	fi
	$(VENV_PY) -m pip install --disable-pip-version-check -q -r requirements.txt
	touch $@

wheels: $(SETUP_STAMP)
	$(VENV_PY) tools/fetch_wheels.py

validate: $(SETUP_STAMP)
	$(if $(BLENDER_EXT),,$(error blender_ext.py not found in the bpy wheel under $(VENV)))
	$(VENV_PY) $(BLENDER_EXT) validate .

build: setup wheels validate
	mkdir -p $(DIST)
	rm -f $(DIST)/*.zip
	$(if $(BLENDER_EXT),,$(error blender_ext.py not found in the bpy wheel under $(VENV)))
	$(VENV_PY) $(BLENDER_EXT) build --source-dir . --output-dir $(DIST) --split-platforms
	@echo "Built packages:"; ls -1 $(DIST)/*.zip

test: setup wheels
	$(VENV_PY) -m pytest tests -q $(PYTEST_ARGS)

test-core: setup
	$(VENV_PY) -m pytest tests/core -q $(PYTEST_ARGS)

lint:
	python3 tools/lint.py

docs:
	python3 tools/architecture.py

# the GLSL's copy of the Python constants (it imports the add-on: the venv's Python)
shaders: setup
	$(VENV_PY) tools/glsl_constants.py

demo: setup
	$(VENV_PY) bench/demo.py --out out/demo

bench: setup
	$(VENV_PY) bench/bench_precompute.py

# Production scale (issue 20): Suzanne of 25k / 100k / 250k / 500k vertices on a 64^2
# ground, one process per size: precompute, peak memory, stored bytes and .blend growth
# per point, AUTO's choice against the precompute, F12 per method, ESC (long: an hour or
# more on 2 cores; SCALE_ARGS="--vertices 25000 100000" for fewer sizes); then 16 and 64
# collection instances of a 5k-vertex Suzanne, time and bytes per instance
# (SCALE_ARGS="--instances 1000" for issue 31's target).
SCALE_ARGS ?=
bench-scale: setup
	$(VENV_PY) bench/bench_scale.py $(SCALE_ARGS)

# Dynamic objects (shadow fields, addon/frame/dynamic.py): field precompute time and stored size
# per detail (LOW/MEDIUM/HIGH), and frame time with 1/4/16 dynamic objects against the same
# scene static, relit and moved (about 5 minutes on 2 cores; DYNAMIC_ARGS="--big" adds a
# 60k-vertex object, "--append docs/measurements.md" records the run).
DYNAMIC_ARGS ?=
bench-dynamic: setup
	$(VENV_PY) bench/bench_dynamic.py $(DYNAMIC_ARGS)

# Frame cost per lamp (issue 31): an interior under 0/1/4/16/64 spots, frames with the shadow
# maps cached and with every lamp moved, the least-squares ms per lamp (about a minute on 2
# cores; LAMPS_ARGS="--append docs/measurements.md" records the run).
LAMPS_ARGS ?=
bench-lamps: setup
	$(VENV_PY) bench/bench_lights.py --lamps $(LAMPS_ARGS)

# Relit frames against Workbench (issue 32): every method on the diffuse, sun, glossy,
# textured, three-lamp and 1080p teapot scenes, relit F12 and viewport frames as ratios to
# Workbench in one run, with the profile of a relit F12 (about 15 minutes on 2 cores;
# FRAMES_ARGS="--append docs/measurements.md" records the run).
FRAMES_ARGS ?=
bench-frames: setup
	$(VENV_PY) bench/bench_frames.py $(FRAMES_ARGS)

# A GPU figure (issue 32, item 4): every method's relit F12 and viewport frame in ms beside
# Workbench's and EEVEE's F12 (16 render samples) on the same scenes at 1920x1080, the GPU named
# in the header; run it on a machine with an NVIDIA GPU (EGL: bench/gpu_frames.py's docstring).
# On llvmpipe it warns and gives ratios only; GPU_ARGS="--size 320 180 --kinds diffuse" for a
# quick check, "--append docs/measurements.md" records the run.
GPU_ARGS ?=
bench-gpu: setup
	$(VENV_PY) bench/gpu_frames.py $(GPU_ARGS)

# Each method against REFERENCE on its held-out scenes (long: tens of minutes on 2 cores).
bench-methods: setup
	$(VENV_PY) bench/bench_methods.py
	$(VENV_PY) bench/bench_blocks.py
	$(VENV_PY) bench/bench_rsl.py
	$(VENV_PY) bench/bench_ssdf_sg.py

# Light that bounces (issue 29): every method against Cycles with 4 diffuse bounces and
# direct, F12 with and without bounces, on the Cornell box, the window-lit room and an object
# on a coloured ground; pictures of the room and the box (about 20 minutes on 2 cores).
BOUNCE_ARGS ?= --pictures docs/images
bench-bounces: setup
	$(VENV_PY) bench/bench_bounces.py $(BOUNCE_ARGS)

# The scene fuzzer (issue 31): random scenes -- meshes open, closed and degenerate, instances
# of instances, particles, lamps of every type, textured materials, rotated HDRIs, every method
# -- each built, precomputed and rendered in a fresh process: no crash, finite non-negative
# pixels, clear refusals, time and memory within tests/fuzz/check.py's bounds (about 4 s a
# scene on 2 cores: 500 scenes in 35 minutes).  A failing seed is printed for
# tests/fuzz/test_fuzz.py's REGRESSION_SEEDS, which make test runs.
FUZZ_N ?= 500
FUZZ_SEED0 ?= 0
fuzz: setup
	$(VENV_PY) tests/fuzz/run.py --n $(FUZZ_N) --seed0 $(FUZZ_SEED0)

# Speed/error report of every method on the held-out scenes (out/report/<scene>/index.html).
report: setup
	$(VENV_PY) bench/report.py --cycles --stability

clean:
	rm -rf $(DIST) out .pytest_cache
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV) wheels
