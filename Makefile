# anisocb — `make demo` runs the main job, `make test` runs every check.
CARGO ?= cargo

.PHONY: all build test lint c-example c-example-if-cc rust-example fmt-check clippy check-features cuda-parity dist-test bench bench-peers demo weights dist fixtures onnx blender-addon blender-test blender-screenshot blender-usd-test usd-test clean

all: build

build:
	$(CARGO) build --release

## test: format check + clippy (-D warnings) + every test in release mode + feature builds +
## the CUDA parity tests compiled with the feature + the C ABI example where a C compiler
## exists (required under CI, whose .ci/run installs one) + the portable build's tests
test: fmt-check clippy check-features
	$(CARGO) test --release
	@# The bf16 convolution again on its AVX512_BF16 dot-product kernel (a CPU without AMX).
	ANISOCB_NO_AMX=1 $(CARGO) test --release --test conv_bf16_vs_ref
	$(MAKE) cuda-parity
	$(MAKE) cuda-emu-if-tools
	$(MAKE) rust-example
	$(MAKE) c-example-if-cc
	$(MAKE) dist-test

## examples/upscale_obj.rs, built on the library alone (--no-default-features: the five core
## crates), upscales OBJ frames to the bytes `anisocb upscale` writes.
R_OUT = target/rust-example
rust-example:
	$(CARGO) build --release
	rm -rf $(R_OUT) && mkdir -p $(R_OUT)
	target/release/anisocb simulate --scenario drop --frames 12 --obj --out $(R_OUT)/sim >/dev/null
	target/release/anisocb upscale $(R_OUT)/sim/obj --out $(R_OUT)/cli >/dev/null 2>&1
	$(CARGO) run --release --no-default-features --example upscale_obj -- $(R_OUT)/sim/obj $(R_OUT)/lib
	diff -r -x 'upscale*.json' $(R_OUT)/cli $(R_OUT)/lib && echo "✓ the library example wrote the CLI's bytes"

## The C ABI (include/anisocb.h) as a static and a shared library; examples/c/upscale_frames.c
## compiled against each with the system C compiler, run on 24 frames of a simulated drape and
## checked bit for bit against `anisocb upscale` (plain, with --temporal 2, and with --physics
## --physics-pin corners); then
## anisocb_push called from Rust, checked to allocate nothing per frame after warm-up
## (tests/upscaler_allocations.rs with --features capi), and its physics options checked
## (tests/c_abi_physics.rs). ≈ 2 min.
CC ?= cc
C_OUT = target/c-example
c-example:
	$(CARGO) rustc --release --lib --no-default-features --features capi --crate-type staticlib,cdylib
	$(CARGO) build --release
	rm -rf $(C_OUT) && mkdir -p $(C_OUT)
	$(CC) -O2 -Wall -Wextra -Werror -std=c11 -Iinclude examples/c/upscale_frames.c \
		target/release/libanisocb.a -lpthread -ldl -lm -o $(C_OUT)/upscale_static
	$(CC) -O2 -Wall -Wextra -Werror -std=c11 -Iinclude examples/c/upscale_frames.c \
		-Ltarget/release -lanisocb -Wl,-rpath,$(CURDIR)/target/release -o $(C_OUT)/upscale_shared
	target/release/anisocb simulate --scenario drape --frames 24 --obj --out $(C_OUT)/sim >/dev/null
	target/release/anisocb upscale $(C_OUT)/sim/obj --out $(C_OUT)/cli >/dev/null 2>&1
	target/release/anisocb upscale $(C_OUT)/sim/obj --out $(C_OUT)/cli-t2 --temporal 2 >/dev/null 2>&1
	target/release/anisocb upscale $(C_OUT)/sim/obj --out $(C_OUT)/cli-phys --physics --physics-pin corners >/dev/null 2>&1
	$(C_OUT)/upscale_static $(C_OUT)/sim/obj $(C_OUT)/cli 24
	$(C_OUT)/upscale_shared $(C_OUT)/sim/obj $(C_OUT)/cli-t2 24 2
	$(C_OUT)/upscale_static $(C_OUT)/sim/obj $(C_OUT)/cli-phys 24 0 corners
	$(CARGO) test --release --features capi --test upscaler_allocations --test c_abi_physics --test c_abi_memory --test c_abi_mesh

c-example-if-cc:
	@if command -v $(CC) >/dev/null 2>&1; then $(MAKE) c-example; \
	elif [ -n "$$CI" ]; then echo "✗ no C compiler ($(CC)) under CI: .ci/run should have installed one"; exit 1; \
	else echo "✗ no C compiler ($(CC)): make c-example skipped"; fi

## tests/cuda_parity.rs built with `--features cuda` (cudarc loads the driver at run time, so no
## CUDA toolkit is needed): on a machine with an NVIDIA GPU every check runs on it; without one
## each prints "skipped: no CUDA device (…)" and passes, and this target says which it was.
cuda-parity:
	$(CARGO) test --release --features cuda --test cuda_parity -- --nocapture --test-threads 1 2>&1 | tee target/cuda-parity.log
	@if grep -q "^test result: ok" target/cuda-parity.log; then \
		if grep -q "skipped: no CUDA device" target/cuda-parity.log; then \
			echo "✗ CUDA parity tests compiled with --features cuda; no CUDA device here, so they were skipped"; \
		else echo "✓ CUDA parity tests ran on the GPU"; fi; \
	else echo "✗ CUDA parity tests failed"; exit 1; fi

## The CUDA kernels without a GPU: kernels/emu/check_kernels.py compiles kernels/*.cu with g++
## in a CPU emulation (blocks of threads, shared memory, barriers, mma.sync lane by lane) and
## checks every kernel against NumPy, and each fusion of device-resident training against the
## kernels it replaces, bit for bit. ≈ 15 s. Needs g++ and numpy: skipped without them, except
## under CI (.ci/run installs them).
cuda-emu:
	@mkdir -p target
	@if python3 kernels/emu/check_kernels.py > target/cuda-emu.log 2>&1; then \
		echo "✓ CUDA kernels in the CPU emulation: $$(grep -c '^ok' target/cuda-emu.log) checks passed"; \
	else grep -v '^ok' target/cuda-emu.log | tail -30; echo "✗ CUDA kernels in the CPU emulation failed (target/cuda-emu.log)"; exit 1; fi

cuda-emu-if-tools:
	@if command -v g++ >/dev/null 2>&1 && python3 -c "import numpy" >/dev/null 2>&1; then $(MAKE) cuda-emu; \
	elif [ -n "$$CI" ]; then echo "✗ no g++ or numpy under CI: .ci/run should have installed them"; exit 1; \
	else echo "✗ no g++ or numpy: make cuda-emu skipped"; fi

## The portable build's tests, once: the whole suite compiled for x86-64-v3 (AVX2 + FMA, no
## AVX-512: `wide` then runs its 256-bit paths), as `make dist` builds the shipped binary.
## ≈ 10 min on 2 cores (a second build of every crate); without debug line tables, which this
## build does not need, its folder takes about half the disk (a full disk breaks the linker).
dist-test:
	CARGO_PROFILE_RELEASE_DEBUG=0 RUSTFLAGS="-C target-cpu=x86-64-v3" $(CARGO) test --release --target-dir target/dist-test

fmt-check:
	$(CARGO) fmt --all -- --check

clippy:
	$(CARGO) clippy --release --all-targets -- -D warnings

lint: fmt-check clippy

## The core builds without the CLI crates, and the CUDA path builds without a CUDA toolkit.
check-features:
	$(CARGO) build --release --lib --no-default-features
	@if $(CARGO) build --release --features cuda >/dev/null 2>&1; then \
		echo "✓ --features cuda builds (cudarc, dynamic loading)"; \
	else \
		echo "✗ --features cuda failed to build:"; $(CARGO) build --release --features cuda; exit 1; \
	fi
	@if command -v nvidia-smi >/dev/null 2>&1; then echo "✓ nvidia-smi found: CUDA parity tests can run"; \
	else echo "✗ no NVIDIA GPU here: CUDA parity tests report 'skipped: no CUDA device'"; fi

bench:
	$(CARGO) run --release -- bench

## anisocb vs ONNX Runtime, OpenVINO (the nets) and JAX/XLA, interleaved rounds, medians and
## ratios (needs Python and pip; not part of `make test`; ≈ 4 min on 2 cores after the build).
## Writes target/bench-peers.md.
bench-peers:
	test -x .venv-peers/bin/python || python3 -m venv .venv-peers
	.venv-peers/bin/pip install -q -r benches/peers/requirements.txt
	$(CARGO) bench --bench peers --no-run
	.venv-peers/bin/python benches/peers/run.py $(GROUPS)

demo:
	$(CARGO) run --release -- demo

## Retrain the shipped model from scratch (simulate, dataset, train; ≈ 30 min on 2 cores).
weights: build
	./weights/make_weights.sh

## Export the shipped model to ONNX and check ONNX Runtime against anisocb (needs Python and
## pip; not part of `make test`). Writes target/anisocb-x2.onnx.
onnx: build
	test -x .venv-onnx/bin/python || python3 -m venv .venv-onnx
	.venv-onnx/bin/pip install -q -r tests/onnx/requirements.txt
	.venv-onnx/bin/python tests/onnx/export_onnx.py weights/anisocb-x2.npz target/anisocb-x2.onnx
	.venv-onnx/bin/python tests/onnx/check_onnx.py --onnx target/anisocb-x2.onnx

## The Blender add-on (blender/anisocb_addon/) as a zip for Edit > Preferences > Add-ons >
## Install from Disk (docs/blender.md).
blender-addon:
	mkdir -p target && rm -f target/anisocb_addon.zip
	cd blender && zip -qr ../target/anisocb_addon.zip anisocb_addon -x '*__pycache__*' '*.pyc'
	@echo "Blender add-on: target/anisocb_addon.zip"

## The add-on in real Blender, headless (tests/blender/test_addon.py; not part of `make test`).
## Needs Python 3.11 with Blender's bpy module: BLENDER_PY is that Python, set up with
##   python3.11 -m venv .venv-bpy && .venv-bpy/bin/pip install -r tests/blender/requirements.txt
## (bpy==4.5.4, a large download), then `make blender-test BLENDER_PY=.venv-bpy/bin/python`.
BLENDER_PY ?= python3
## USD in and out (feature `usd`, not in `make test`).
usd-test:
	$(CARGO) test --release --features usd --test usd_roundtrip

blender-test: build blender-addon
	$(BLENDER_PY) tests/blender/test_addon.py --anisocb target/release/anisocb --zip target/anisocb_addon.zip

## The README's picture of the panel (docs/blender-panel.png), taken in a real Blender window:
## needs Blender 4.2+ itself (BLENDER, not the bpy module: it draws no UI), xvfb-run and xwd
## (Debian: xvfb x11-apps). Presses Upscale as the button does and fails if the modal run does
## not bring the HR object back (tests/blender/screenshot_panel.py).
BLENDER ?= blender
SHOT_HOME ?= /tmp/anisocb-shot
blender-screenshot: build
	rm -rf $(SHOT_HOME) && mkdir -p $(SHOT_HOME)
	HOME=$(SHOT_HOME) $(BLENDER) -b --factory-startup --python-expr "import bpy; bpy.context.preferences.view.show_splash = False; bpy.ops.wm.save_userpref(); bpy.ops.wm.save_as_mainfile(filepath='$(SHOT_HOME)/start.blend')"
	HOME=$(SHOT_HOME) xvfb-run -a -s "-screen 0 1600x900x24" $(BLENDER) $(SHOT_HOME)/start.blend \
		--python tests/blender/screenshot_panel.py -- --anisocb target/release/anisocb --out docs/blender-panel.png

## USD from Blender's exporter through `anisocb upscale` (feature `usd`) and back through its
## importer (tests/blender/test_usd.py; BLENDER_PY as for blender-test).
## USD_PY: a Python with usd-core (tests/blender/requirements-usd.txt) for Pixar's reader; empty: skipped.
USD_PY ?=
blender-usd-test:
	$(CARGO) build --release --features usd
	$(BLENDER_PY) tests/blender/test_usd.py --anisocb target/release/anisocb $(if $(USD_PY),--pxr-python $(USD_PY))

## Regenerate reference .npy files (needs Python; `make test` does not).
fixtures:
	python3 -m pip install -q -r tests/fixtures/requirements.txt
	cd tests/fixtures && for g in gen_*.py; do python3 $$g || exit 1; done

## Portable single binary for x86-64-v3 (AVX2 + FMA), weights embedded.
dist:
	RUSTFLAGS="-C target-cpu=x86-64-v3" $(CARGO) build --profile dist --target-dir target/dist
	@echo "portable binary: target/dist/dist/anisocb (baseline x86-64-v3)"

clean:
	$(CARGO) clean
