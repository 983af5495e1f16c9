#!/usr/bin/env bash
# Every check and every test: formatting, lints, type checks and docs (Rust, then
# Python), then the Rust unit and integration tests (release), then pytest against the
# installed extension (which includes the stub check with mypy.stubtest and the quick
# subset of the diagnosis suite, both halves, held to the suite's checks), then the
# measured-data benchmark.
set -euo pipefail
export BOUCWEN_TEST=1
. "$(dirname "$0")/setup_env.sh"
echo "== cargo fmt --check"
cargo fmt --check
echo "== cargo clippy --all-targets --all-features -- -D warnings"
cargo clippy --all-targets --all-features -- -D warnings
echo "== cargo doc --no-deps (warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps
echo "== ruff check python tests benches examples"
ruff check python tests benches examples
echo "== ruff format --check python tests benches examples"
ruff format --check python tests benches examples
echo "== mypy (strict, python/boucwen)"
mypy
echo "== cargo test --release --features ffi"
cargo test --release --features ffi
echo "== examples"
cargo run --release --quiet --example identify
python examples/fit_and_identify.py
echo "== pytest"
python -m pytest -q -p no:cacheprovider tests
echo "== python -m boucwen.experiments.measured --out out/measured (the measured-data benchmark; fails when a target fails)"
python -m boucwen.experiments.measured --out out/measured
echo "== no_std core for thumbv7em-none-eabihf (Cortex-M4F/M7)"
rustup target add thumbv7em-none-eabihf
cargo rustc --release --lib --crate-type rlib --no-default-features --target thumbv7em-none-eabihf
