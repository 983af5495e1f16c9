#!/usr/bin/env bash
# Every test: the Rust unit and integration tests (release), then pytest against the
# installed extension (which includes the stub check with mypy.stubtest).
set -euo pipefail
export BOUCWEN_TEST=1
. "$(dirname "$0")/setup_env.sh"
echo "== cargo test --release --features ffi"
cargo test --release --features ffi
echo "== pytest"
python -m pytest -q -p no:cacheprovider tests
echo "== no_std core for thumbv7em-none-eabihf (Cortex-M4F/M7)"
rustup target add thumbv7em-none-eabihf
cargo rustc --release --lib --crate-type rlib --no-default-features --target thumbv7em-none-eabihf
