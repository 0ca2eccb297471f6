# anisocb — `make demo` runs the main job, `make test` runs every check.
CARGO ?= cargo

.PHONY: all build test lint fmt-check clippy check-features bench bench-peers demo weights dist fixtures onnx clean

all: build

build:
	$(CARGO) build --release

## test: format check + clippy (-D warnings) + every test in release mode + feature builds
test: fmt-check clippy check-features
	$(CARGO) test --release

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

## anisocb vs ONNX Runtime and JAX/XLA, interleaved rounds, medians and ratios (needs Python and
## pip; not part of `make test`; ≈ 2 min on 2 cores after the build). Writes target/bench-peers.md.
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
