#!/usr/bin/env bash
# The Panda study of docs/panda-study.md: every row of its table, from `chaosctl config --preset
# panda-paper` (the paper's recipe) with one change per variant. Usage: [TABLE_ONLY=1] [CHAOSD_BIN=DIR]
# scripts/panda-study/run.sh [out-dir]
# Needs a release build (cargo build --release -p client). About a minute on one core.
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-out/panda-study}
mkdir -p "$out"
ctl=${CHAOSD_BIN:-target/release}/chaosctl
$ctl config --preset panda-paper > "$out/panda.toml"

# variant NAME 'sed expressions' : writes $out/NAME.toml from the preset. A key the printed file
# leaves out (a zero `null_damping`) is added after its section's header, not substituted.
variant() {
  sed -e "$2" "$out/panda.toml" > "$out/$1.toml"
}
# The safety filter off (its section's `enabled` only: [feedback] has one too), the feedback on from t = 0.
common='/^\[safety\]/,/^\[/ s/^enabled = true/enabled = false/; s/^t_on = 60.0/t_on = 0.0/'
variant pure        "$common; s/^alpha = 20.0/alpha = 0.0/; s/^mu = 1.0/mu = 0.0/"
variant pyragas     "$common; s/^alpha = 20.0/alpha = 0.0/; s/^mu = 1.0/mu = 3.0/; s/^projection = .*/projection = \"full\"/"
variant pyragas-ns  "$common; s/^alpha = 20.0/alpha = 0.0/; s/^mu = 1.0/mu = 3.0/"
variant centring    "$common; s/^mu = 1.0/mu = 0.0/"
variant both        "$common"
variant both-full   "$common; s/^projection = .*/projection = \"full\"/"
variant both-mu3    "$common; s/^mu = 1.0/mu = 3.0/"
variant manip       "$common; s/^secondary = .*/secondary = \"manipulability\"/; s/^alpha = 20.0/alpha = 5.0/"
variant damping     "$common; s/^alpha = 20.0/alpha = 0.0/; s/^mu = 1.0/mu = 0.0/; s/^secondary = .*/secondary = \"none\"/; /^null_damping = /d; /^\[law\]/a null_damping = 2.0"
variant barrier     "s/^alpha = 20.0/alpha = 0.0/; s/^mu = 1.0/mu = 0.0/"
variant barrier-ns  "s/^alpha = 20.0/alpha = 0.0/; s/^t_on = 60.0/t_on = 0.0/"
variant pose        "$common; s/^kind = \"position\"/kind = \"pose\"/"
variant pose-pure   "$common; s/^kind = \"position\"/kind = \"pose\"/; s/^alpha = 20.0/alpha = 0.0/; s/^mu = 1.0/mu = 0.0/"
variant offaxis     "$common; s/^tool = .*/tool = [0.05, 0.0, 0.1034]/"
variant offaxis-pure "$common; s/^tool = .*/tool = [0.05, 0.0, 0.1034]/; s/^alpha = 20.0/alpha = 0.0/; s/^mu = 1.0/mu = 0.0/"
cp "$out/panda.toml" "$out/preset.toml"

printf '| variant | residual before → final (rad/s) | drift / period (rad) | max speed (rad/s) | min margin (rad) | filter active (s) | λ_max (1/s) |\n|---|---|---|---|---|---|---|\n' > "$out/table.md"
for v in pure pyragas pyragas-ns centring both both-full both-mu3 manip damping barrier barrier-ns pose pose-pure offaxis offaxis-pure preset; do
  $ctl simulate --config "$out/$v.toml" --json > "$out/$v.json"
  lam=$($ctl lyapunov --config "$out/$v.toml" --duration 150 --window 50:150 \
        | sed -n 's/^ *λ_max *\([^ ]*\) ± \([^ ]*\) .*/\1 ± \2/p')
  python3 - "$out/$v.json" "$v" "$lam" >> "$out/table.md" <<'PY'
import json, sys
d = json.load(open(sys.argv[1])); v = sys.argv[2]; lam = sys.argv[3]
f = lambda x: "n/a" if x is None else f"{x:.2e}"
print(f"| {v} | {f(d['period_residual_before'])} → {f(d['period_residual_final'])} | {f(d['drift_per_period'])} "
      f"| {d['max_joint_speed']:.2f} | {f(d['min_joint_margin'])} | {d['safety_active_time']:.1f} | {lam} |")
PY
done
cat "$out/table.md"
# TABLE_ONLY=1: the table alone (tests/tests/study_tables.rs holds the book's to it).
[ "${TABLE_ONLY:-0}" = 1 ] && exit 0

# The μ sweeps (with centring: the preset without the filter and with feedback from t = 0;
# without: the pyragas-ns variant) and the arm figure of the preset.
$ctl sweep --config "$out/both.toml" --mu 0:3:0.25 --duration 150 --window 50:150 --output "$out/sweep"
$ctl sweep --config "$out/pyragas-ns.toml" --mu 0:3:0.25 --duration 150 --window 50:150 --output "$out/sweep-no-centring"
$ctl arm-figure --preset panda-paper --from 195 --frames 6 --output "$out/arm"
$ctl poincare --config "$out/both.toml" --duration 300 --transient 100 --output "$out/poincare"
$ctl poincare --config "$out/pyragas-ns.toml" --duration 300 --transient 100 --output "$out/poincare-no-centring"
