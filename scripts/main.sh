#!/usr/bin/env bash
# The main job: the paper's experiment on the simulated bench (traditional vs online
# identification, Tables 1 and 2, Figs. 6-9), the paper's method on the paper's own
# model and sensor (paper_exact), the residual diagnosis of the measured
# micromanipulator record (in $BOUCWEN_DATA or ../shared/data beside the repository;
# skipped, and said so, where neither holds it), the measured-data benchmark (base vs
# returned model on unseen data), the hysteretic oscillator on the Bouc-Wen benchmark's
# training record (where the data directory holds it; a few seconds), then the
# closed-loop tracking experiment with hysteresis compensation.
# Results go to out/ (JSON, CSV and PNG figures).
set -euo pipefail
. "$(dirname "$0")/setup_env.sh"
mkdir -p out
echo "== boucwen reproduce --out out/reproduce"
boucwen reproduce --out out/reproduce
echo "== python -m boucwen.experiments.paper_exact --out out/paper_exact"
python -m boucwen.experiments.paper_exact --out out/paper_exact
data="${BOUCWEN_DATA:-../shared/data}/yan9a-piezo-micromanipulator"
if [ -f "$data/Model_Vi_Do.dat" ]; then
  echo "== boucwen diagnose $data/Model_Vi_Do.dat"
  boucwen diagnose "$data/Model_Vi_Do.dat" --json out/micromanipulator/report.json \
    --predictions out/micromanipulator/predictions.csv --plot out/micromanipulator/diagnosis.png
else
  echo "== skipped: the diagnosis of the measured record ($data/Model_Vi_Do.dat is not on this machine;" \
    "set BOUCWEN_DATA to a folder holding yan9a-piezo-micromanipulator/)"
fi
echo "== python -m boucwen.experiments.measured --out out/measured"
# Status 1 when a target of either benchmark fails: the tracking still runs, the job fails after it.
measured=0
python -m boucwen.experiments.measured --out out/measured || measured=$?
benchmark="${BOUCWEN_DATA:-../shared/data}/bouc-wen-benchmark/train_multisine.csv"
if [ -f "$benchmark" ]; then
  echo "== python -m boucwen.experiments.bouc_wen_benchmark --out out/bouc_wen_benchmark"
  python -m boucwen.experiments.bouc_wen_benchmark --out out/bouc_wen_benchmark || measured=$?
else
  echo "== skipped: the Bouc-Wen benchmark ($benchmark is not on this machine;" \
    "set BOUCWEN_DATA to a folder holding bouc-wen-benchmark/)"
fi
echo "== boucwen track --out out/track"
boucwen track --out out/track
exit "$measured"
