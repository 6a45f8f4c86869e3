#!/usr/bin/env bash
# The robustness check of docs/panda-study.md: 12 starts within ±0.5 rad of the ready pose (a
# fixed pseudo-random draw), the law alone (filter off, feedback from t = 0), 60 s, for the
# preset and for variants with null-space damping. A start counts when its period residual ends
# ≤ 1e-3 rad/s with every joint inside its position and speed limits throughout.
# Usage: scripts/panda-study/starts.sh [out-dir]. Needs a release build. About 2 minutes.
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-out/panda-starts}
mkdir -p "$out"
ctl=${CHAOSD_BIN:-target/release}/chaosctl
$ctl config --preset panda-paper > "$out/panda.toml"

# The i-th start: the ready pose plus a uniform draw in [−0.5, 0.5) per joint.
start() {
  awk -v s="$1" 'BEGIN { srand(s * 7919); split("0.0 -0.785 0.0 -2.356 0.0 1.571 0.785", r, " ");
    for (j = 1; j <= 7; j++) printf "%s%.4f", (j > 1 ? "," : ""), r[j] + rand() - 0.5; print "" }'
}

# variant ALPHA NULL_DAMPING MU: one row. `null_damping` is left out of the printed file while it
# is 0, so it is added after [law], not substituted; each run is judged on its JSON summary.
variant() {
  local cfg="$out/a$1_kd$2_mu$3.toml" good=0 line=""
  sed -e "s/^alpha = .*/alpha = $1/" -e "/^null_damping = /d" -e "/^\[law\]/a null_damping = $2" \
    -e "s/^mu = .*/mu = $3/" "$out/panda.toml" > "$cfg"
  for i in $(seq 1 12); do
    if $ctl simulate --config "$cfg" --q0="$(start "$i")" --safety off --t-on 0 --duration 60 --json \
      | python3 -c 'import json, sys
d = json.load(sys.stdin)
r = d["period_residual_final"]
sys.exit(not (r is not None and r <= 1e-3 and d["max_speed_ratio"] <= 1.0 and d["min_joint_margin"] > 0))'
    then
      good=$((good + 1)); line="$line ✓"
    else
      line="$line ✗"
    fi
  done
  printf '| %s | %s | %s | %d of 12 |%s |\n' "$1" "$2" "$3" "$good" "$line"
}

echo "| α | k_d | μ | residual ≤ 1e-3 within limits | starts 1-12 |"
echo "|---|---|---|---|---|"
variant 20.0 0.0 1.0
variant 20.0 1.0 0.0
variant 20.0 1.0 0.25
variant 20.0 2.0 0.75
variant 40.0 2.0 0.25
