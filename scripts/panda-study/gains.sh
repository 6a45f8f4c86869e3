#!/usr/bin/env bash
# The gain study of docs/panda-study.md ("How fast, and what makes it faster"): for each variant
# of `chaosctl config --preset panda-paper` (the paper's recipe), the period-T cycle of its loop
# without feedback and the leading Floquet multiplier of the delayed loop on it at each μ, by `chaosctl orbits`.
# Usage: scripts/panda-study/gains.sh [out-dir]. Needs a release build (cargo build --release -p
# client). About 3 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-out/panda-gains}
mkdir -p "$out"
ctl=${CHAOSD_BIN:-target/release}/chaosctl
$ctl config --preset panda-paper > "$out/panda.toml"

# row ALPHA NULL_DAMPING: one line of the table.
row() {
  local name="alpha${1}_kd${2}"
  # `null_damping` is left out of the printed file while it is 0: added after [law], not substituted.
  sed -e "s/^alpha = .*/alpha = $1/" -e "/^null_damping = /d" -e "/^\[law\]/a null_damping = $2" \
    "$out/panda.toml" > "$out/$name.toml"
  $ctl orbits --config "$out/$name.toml" --seed-mu 1 --seed-duration 120 --mu 0:1.5:0.25 \
    --average 40 --output "$out/$name" > "$out/$name.txt" 2>&1 || true
  local rho0 fastest
  rho0=$(grep -o 'largest Floquet multiplier |ρ| = [0-9.]*' "$out/$name.txt" | head -1 | awk '{print $NF}')
  fastest=$(grep -o 'fastest at μ = [0-9.]*: [-+0-9.]* /s' "$out/$name.txt" | head -1 \
    | sed 's/fastest at μ = \([0-9.]*\): \([-+0-9.]*\) .*/μ = \1: \2/')
  local lam0="—"
  [ -n "$rho0" ] && lam0=$(awk -v r="$rho0" 'BEGIN { printf "%+.4f", log(r) / 2.0 }')
  printf '| %s | %s | %s | %s | %s |\n' "$1" "$2" "${rho0:-no orbit}" "$lam0" "${fastest:-none stable}"
}

echo "| α | null damping k_d | largest \\|ρ\\| at μ = 0 | ln\\|ρ\\|/T at μ = 0 (1/s) | fastest ln\\|ρ₁\\|/T with feedback (1/s), μ = 0.25…1.5 |"
echo "|---|---|---|---|---|"
for kd in 0.0 0.5 1.0 2.0 3.0 5.0; do row 20.0 "$kd"; done
for a in 10.0 40.0 80.0; do row "$a" 0.0; row "$a" 2.0; done
row 160.0 4.0
row 160.0 8.0   # the `panda` preset's gains
