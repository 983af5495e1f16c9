#!/usr/bin/env bash
# The wheel, built and tried where there is no Rust (a step of scripts/test.sh; runs alone too):
#
#   bash scripts/wheel.sh
#
# 1. `maturin build --release --zig` into dist/: one abi3 wheel for CPython >= 3.10, tagged
#    manylinux2014 (glibc >= 2.17; pyproject.toml, [tool.maturin] compatibility). Zig (the
#    ziglang package from PyPI, installed into .venv with maturin) links it against glibc
#    2.17's symbols whatever this host's glibc. scripts/setup_env.sh builds the extension of
#    .venv the same way, so after it this build only packs the wheel.
# 2. A fresh virtual environment in a temporary folder, with no cargo or rustc on PATH: the
#    wheel installed there (NumPy, SciPy and Matplotlib from PyPI), then scripts/wheel_smoke.py
#    run from that folder, outside the repository, so only the installed package is imported.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
python=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$python" -m venv .venv
fi
.venv/bin/python -m pip install -q "maturin>=1.5,<2" ziglang
rm -f dist/boucwen-*.whl
# maturin finds zig as `python3 -m ziglang`: .venv's python first on PATH. The same build as
# scripts/setup_env.sh's (same options, target/x86_64-unknown-linux-gnu): after it, only
# the packing is left.
PATH="$root/.venv/bin:$PATH" .venv/bin/maturin build --release --zig --compatibility manylinux2014 --out dist
wheels=(dist/boucwen-*.whl)
if [ "${#wheels[@]}" != 1 ] || [ ! -f "${wheels[0]}" ]; then
  echo "wheel.sh: expected one wheel in dist/, found: ${wheels[*]}" >&2
  exit 1
fi
wheel="$root/${wheels[0]}"
case "$(basename "$wheel")" in
  *-cp310-abi3-*manylinux2014_x86_64*.whl | *-cp310-abi3-*manylinux_2_17_*.whl) ;;
  *)
    echo "wheel.sh: $(basename "$wheel") is not an abi3 manylinux2014 wheel" >&2
    exit 1
    ;;
esac
echo "== wheel: $(basename "$wheel"), $(du -k "$wheel" | cut -f1) kB ($(stat -c %s "$wheel") bytes)"

# PATH without any folder that holds cargo or rustc (~/.cargo/bin, a system Rust), nor .venv.
clean_path=""
IFS=: read -r -a dirs <<<"$PATH"
for d in "${dirs[@]}"; do
  if [ -z "$d" ] || [ -e "$d/cargo" ] || [ -e "$d/rustc" ]; then
    continue
  fi
  case "$d" in "$root"/*) continue ;; esac
  clean_path="${clean_path:+$clean_path:}$d"
done
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
echo "== a fresh virtual environment in $tmp, no Rust on PATH"
"$python" -m venv "$tmp/venv"
mkdir "$tmp/run"
cp scripts/wheel_smoke.py "$tmp/run/"
cd "$tmp/run"
run_clean() {
  env -u VIRTUAL_ENV -u PYTHONPATH -u PYTHONHOME PATH="$tmp/venv/bin:$clean_path" "$@"
}
if run_clean bash -c 'command -v cargo || command -v rustc'; then
  echo "wheel.sh: a Rust toolchain is still on PATH" >&2
  exit 1
fi
run_clean python -m pip install -q "$wheel"
run_clean python wheel_smoke.py
