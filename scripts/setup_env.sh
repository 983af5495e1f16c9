# Sourced by the other scripts: a virtual environment in .venv with boucwen built
# (release) and installed, plus the test tools and the fleet extra (Dask, pandas,
# pyarrow) when BOUCWEN_TEST=1.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
python=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "== creating .venv"
  "$python" -m venv .venv
fi
# shellcheck disable=SC1091
. .venv/bin/activate
python -m pip install -q --upgrade pip >/dev/null
extras=""
[ "${BOUCWEN_TEST:-0}" = 1 ] && extras="[test,fleet]"
echo "== building and installing boucwen (release build of the Rust extension)"
# A stale build of the extension must never shadow the fresh one.
find python/boucwen -maxdepth 1 -name '_core*.so' -delete
# Built as the wheel is (scripts/wheel.sh): linked by Zig against glibc 2.17's symbols, so
# the two share one build in target/x86_64-unknown-linux-gnu. maturin and Zig (the ziglang
# package) live in .venv, where the build runs (no build isolation).
python -m pip install -q "maturin>=1.5,<2" ziglang
MATURIN_PEP517_ARGS="--zig --compatibility manylinux2014" python -m pip install -q --no-build-isolation ".${extras}"
