#!/usr/bin/env bash
# The test commands (README, "Tests"; docs/testing.md; .ci/run runs both):
#
#   bash scripts/test.sh          every check and every test but the slow ones: formatting,
#                                 lints, type checks and docs (Rust, then Python), the Rust unit
#                                 and integration tests (cargo profile test-release: release code
#                                 without LTO, built once; the example and the C library of
#                                 tests/test_embed.py come from that build), the examples, the
#                                 no_std build, the manylinux2014 wheel (scripts/wheel.sh: built,
#                                 installed in a fresh venv with no Rust on PATH, smoke-tested), then
#                                 pytest on every core against the installed extension (the stub
#                                 check with mypy.stubtest included), the tests marked slow left out
#   bash scripts/test.sh --slow   the slow statistical checks: pytest -m slow on every core (the
#                                 quick diagnosis suite, the long runs, ...) and the measured-data
#                                 benchmark (fails when a target fails)
#
# pytest's exit status 5 (no test collected) fails either command, as every other failure does.
set -euo pipefail
slow=0
case "${1:-}" in
  "") ;;
  --slow) slow=1 ;;
  *)
    echo "usage: bash scripts/test.sh [--slow]" >&2
    exit 2
    ;;
esac
started=$SECONDS
# Prints the seconds since the previous step's start, then the next step's name.
last=$SECONDS
step() {
  echo "   ($((SECONDS - last)) s)"
  last=$SECONDS
  echo "== $*"
}
trap 'echo "   ($((SECONDS - last)) s; $((SECONDS - started)) s in all)"' EXIT
export BOUCWEN_TEST=1
echo "== setup: .venv and the release build of the extension (scripts/setup_env.sh)"
. "$(dirname "$0")/setup_env.sh"
# One pytest worker per logical CPU (pytest-xdist); each test file runs whole in one worker,
# so a module's fixtures are computed once.
pytest_all=(python -m pytest -q -p no:cacheprovider -n logical --dist loadfile)

if [ "$slow" = 1 ]; then
  step "pytest -m slow (every core)"
  "${pytest_all[@]}" -m slow tests
  step "python -m boucwen.experiments.measured --out out/measured (the measured-data benchmark; fails when a target fails)"
  python -m boucwen.experiments.measured --out out/measured
  exit 0
fi

step "cargo fmt --check"
cargo fmt --check
step "ruff check python tests benches examples scripts"
ruff check python tests benches examples scripts
step "ruff format --check python tests benches examples scripts"
ruff format --check python tests benches examples scripts
step "mypy (strict, python/boucwen)"
mypy
step "cargo clippy --all-targets --all-features -- -D warnings"
cargo clippy --all-targets --all-features -- -D warnings
step "cargo doc --no-deps (warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps
# The Rust tests, the example and tests/test_embed.py's C library: one build (Cargo.toml,
# profile test-release).
export BOUCWEN_CARGO_PROFILE=test-release
step "cargo test --profile $BOUCWEN_CARGO_PROFILE --features ffi"
cargo test --profile "$BOUCWEN_CARGO_PROFILE" --features ffi
step "examples"
cargo run --profile "$BOUCWEN_CARGO_PROFILE" --features ffi --quiet --example identify
python examples/fit_and_identify.py
step "no_std core for thumbv7em-none-eabihf (Cortex-M4F/M7)"
rustup target add thumbv7em-none-eabihf
cargo rustc --release --lib --crate-type rlib --no-default-features --target thumbv7em-none-eabihf
step "wheel: maturin build --release --zig (abi3, manylinux2014), installed and smoke-tested without Rust"
bash scripts/wheel.sh
step "pytest -m 'not slow' (every core; the slow checks: bash scripts/test.sh --slow)"
"${pytest_all[@]}" -m "not slow" tests
