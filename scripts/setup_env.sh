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
python -m pip install -q ".${extras}"
