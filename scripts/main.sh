#!/usr/bin/env bash
# The main job on the shipped default data: the paper's experiment on the simulated
# bench (traditional vs online identification, Tables 1 and 2, Figs. 6-9), the
# residual diagnosis of the shipped measured micromanipulator record, then the
# closed-loop tracking experiment with hysteresis compensation.
# Results go to out/ (JSON, CSV and PNG figures).
set -euo pipefail
. "$(dirname "$0")/setup_env.sh"
mkdir -p out
echo "== boucwen reproduce --out out/reproduce"
boucwen reproduce --out out/reproduce
echo "== boucwen diagnose --dataset micromanipulator"
boucwen diagnose --dataset micromanipulator --json out/micromanipulator/report.json \
  --predictions out/micromanipulator/predictions.csv --plot out/micromanipulator/diagnosis.png
echo "== boucwen track --out out/track"
boucwen track --out out/track
