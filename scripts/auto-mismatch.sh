#!/usr/bin/env bash
# The validation of docs/monitor.md, "A plant heavier than the model": `mu = "auto"` against
# fixed gains on a Panda whose plant is not the controller's model, live (the real daemon and
# the rigid-body plant, torque mode, state trigger). The plant's links are MASS_SCALE times the
# description's (default 1.2: 20 % heavier) and it carries PAYLOAD kg at the tool (default 1)
# that the controller does not know. Gains: auto, no feedback, and the two fixed gains the
# model's analysis names for the set-up (the knee it would choose and the fastest), from each
# start. One row per run: when the chaos monitor first said periodic, the period residual at the
# end (the monitor's window), the final μ, tracking RMS and the joint-limit counts.
# Usage: [MASS_SCALE=1.2] [PAYLOAD=1] [DURATION=40] [GAINS="auto 0"] scripts/auto-mismatch.sh [out-dir]
# Needs a release build (cargo build --release --workspace --bins) and jq. About 45 s a run,
# 12 runs.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/auto-mismatch}
scale=${MASS_SCALE:-1.2}
payload=${PAYLOAD:-1}
duration=${DURATION:-40}
bin=${CHAOSD_BIN:-$PWD/target/release}
mkdir -p "$out"
"$bin/chaosctl" config --preset panda > "$out/panda.toml"

# The ready pose, and two starts within ±0.3 rad of it.
starts=(
  "0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785"
  "0.3, -0.6, -0.2, -2.1, 0.25, 1.8, 0.5"
  "-0.25, -1.0, 0.3, -2.6, -0.3, 1.35, 1.05"
)
# The model's knee and fastest gain for this set-up (the daemon's search: docs/monitor.md).
read -r -a gains <<< "${GAINS:-auto 0 0.244 0.359}"

printf '| start | μ | first periodic | residual at the end | final μ | tracking RMS | limit breaches |\n'
printf '|---|---|---|---|---|---|---|\n'
for s in "${!starts[@]}"; do
  for mu in "${gains[@]}"; do
    run="$out/start$((s + 1))-mu$mu"
    cfg="$run.toml"
    sed -e "s/^q0 = .*/q0 = [${starts[$s]}]/" -e 's/^qd0 = .*/qd0 = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]/' \
      "$out/panda.toml" > "$cfg"
    printf '\n[plant.rigid_body]\nmass_scale = %s\npayload = %s\n' "$scale" "$payload" >> "$cfg"
    "$bin/chaosd" demo --config "$cfg" --mode torque --mu "$mu" --t-on 0 \
      --duration "$duration" --namespace "mismatch${s}_${mu//./_}" --output "$run" > "$run.log" 2>&1 || true
    j="$run/daemon-summary.json"
    if [ ! -f "$j" ]; then
      printf '| %d | %s | did not run: %s |\n' $((s + 1)) "$mu" "$(tail -1 "$run.log")"
      continue
    fi
    jq -r --arg s $((s + 1)) --arg mu "$mu" '
      ([.chaos.history[]? | select(.to == "periodic") | .t] | first) as $p
      | .joint_limits as $l
      | "| \($s) | \($mu) | \(if $p then "\($p) s" else "never (\(.chaos.evidence.verdict))" end) | \(.chaos.evidence.residual * 1e7 | round / 1e7) rad/s | \(.chaos.mu * 1000 | round / 1000) | \(.tracking_rms_m * 1e6 | round / 1000) mm | \($l.states_outside + $l.commands_outside) |"' "$j"
  done
done
