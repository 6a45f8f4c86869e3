#!/usr/bin/env bash
# The basin study of docs/panda-study.md: N random starts (a fixed draw), the law alone (filter
# off, feedback from t = 0), for the preset and the variants of the gain study. A start succeeds
# when its period residual is ≤ 1e-3 rad/s over 40-60 s and ≤ 1e-6 over 100-120 s, and every
# joint stays inside its position, speed, acceleration and jerk limits for all 120 s. Starts
# whose circle is out of reach are refused by the config check and left out.
# Usage: [ROBOT=panda|xarm7] [VARIANTS=all|new] [FILTER=on] scripts/panda-study/basins.sh [near|box] [N] [out-dir]
#   near: each joint within ±0.5 rad of the ready pose, rates within ±0.1 rad/s;
#   box:  anywhere in the joint box (10 % in from each limit), rates within ±0.2 rad/s.
# The last variants start the path from rest (task.ramp = 1 s); the ones with null_speed cap the
# centring pull's velocity (law.null_speed), the `panda` preset. VARIANTS=new runs the α = 160 rows.
# Needs a release build. About a minute per variant for N = 100 on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
kind=${1:-near}
n=${2:-100}
robot=${ROBOT:-panda}
out=${3:-out/$robot-basins-$kind}
mkdir -p "$out"
ctl=${CHAOSD_BIN:-$PWD/target/release}/chaosctl
# The arm's ready pose and joint box, and its set-up with the paper's recipe to vary.
case $robot in
  panda)
    ready="0.0 -0.785 0.0 -2.356 0.0 1.571 0.785"
    lo="-2.8973 -1.7628 -2.8973 -3.0718 -2.8973 -0.0175 -2.8973"
    hi="2.8973 1.7628 2.8973 -0.0698 2.8973 3.7525 2.8973"
    $ctl config --preset panda-paper > "$out/panda.toml" ;;
  xarm7)
    ready="0.0 -0.5 0.0 0.7 0.0 1.2 0.0"
    lo="-6.2832 -2.0590 -6.2832 -0.1920 -6.2832 -1.6930 -6.2832"
    hi="6.2832 2.0944 6.2832 3.9270 6.2832 3.1416 6.2832"
    cp examples/own-urdf/xarm7.toml "$out/panda.toml" ;;
  *) echo "ROBOT=$robot: panda or xarm7" >&2; exit 2 ;;
esac

# draw I: "q0 qd0" of start I (awk's generator, seeded by I).
draw() {
  awk -v s="$1" -v kind="$kind" -v ready="$ready" -v low="$lo" -v high="$hi" 'BEGIN {
    srand(s * 104729 + 17);
    split(ready, r, " "); split(low, lo, " "); split(high, hi, " ");
    q = ""; qd = "";
    for (j = 1; j <= 7; j++) {
      if (kind == "box") { m = 0.1 * (hi[j] - lo[j]); v = lo[j] + m + rand() * (hi[j] - lo[j] - 2 * m); w = 0.2 }
      else { v = r[j] + rand() - 0.5; w = 0.1 }
      q = q (j > 1 ? "," : "") sprintf("%.4f", v);
      qd = qd (j > 1 ? "," : "") sprintf("%.4f", w * (2 * rand() - 1));
    }
    print q, qd }'
}

# one CFG I: a line "I verdict residual60 residual120 speed% accel% jerk% margin". The verdict
# is the first limit broken (acceleration-at-start: only in the first 0.1 s), or slow60 /
# slow120, or ok.
one() {
  local cfg=$1 i=$2 q0 qd0 j60 j120 j0
  read -r q0 qd0 <<< "$(draw "$i")"
  run() { $ctl simulate --config "$cfg" --q0="$q0" --qd0="$qd0" --safety off --t-on 0 --duration "$1" --transient 0 --json; }
  if ! j60=$(run 60 2>/dev/null); then
    echo "$i refused"; return
  fi
  j120=$(run 120)
  # The acceleration peak of the first 0.1 s alone: the hand starts at rest on a moving path.
  j0=$(run 0.1)
  python3 - "$i" "$j60" "$j120" "$j0" <<'PY'
import json, sys
i, a, b, z = sys.argv[1], *(json.loads(x) for x in sys.argv[2:])
r60, r120 = a["period_residual_final"], b["period_residual_final"]
sp, ac, je = (100 * b[k] for k in ("max_speed_ratio", "max_accel_ratio", "max_jerk_ratio"))
ac0, mg = 100 * z["max_accel_ratio"], b["min_joint_margin"]
slow = lambda r, tol: r is None or r > tol
v = ("position" if mg <= 0 else "speed" if sp > 100
     else "acceleration-at-start" if ac > 100 and ac == ac0 else "acceleration" if ac > 100
     else "jerk" if je > 100 else "slow60" if slow(r60, 1e-3) else "slow120" if slow(r120, 1e-6)
     else "ok")
print(i, v, r60, r120, f"{sp:.1f}", f"{ac:.1f}", f"{je:.1f}", mg)
PY
}
export -f draw one
export ctl kind ready lo hi

variant() {
  local ramp=${4:-0} speed=${5:-0} name="a$1_kd$2_mu$3_ramp${4:-0}_speed${5:-0}" cfg
  cfg="$out/$name.toml"
  # A zero null_damping or null_speed is left out of the printed file: both are added after
  # [law], not substituted.
  sed -e "s/^alpha = .*/alpha = $1/" -e "/^null_damping = /d" -e "/^null_speed = /d" \
    -e "/^\[law\]/a null_damping = $2\nnull_speed = $speed" \
    -e "s/^mu = .*/mu = $3/" -e "s/^period = 2.0/period = 2.0\nramp = $ramp/" \
    "$out/panda.toml" > "$cfg"
  seq 1 "$n" | xargs -P 2 -I{} bash -c "one '$cfg' {}" | sort -n > "$out/$name.txt"
  local total ok
  total=$(grep -vc refused "$out/$name.txt" || true)
  ok=$(grep -c ' ok ' "$out/$name.txt" || true)
  # Also counted: the starts whose only fault is the first 0.1 s's acceleration.
  local late
  late=$(awk '$2 == "acceleration-at-start" && $3 <= 1e-3 && $4 <= 1e-6 { c++ } END { print c + 0 }' "$out/$name.txt")
  local fails
  fails=$(awk '$2 != "ok" && $2 != "refused" { c[$2]++ } END { for (k in c) printf "%s %d, ", k, c[k] }' "$out/$name.txt")
  printf '| %s | %s | %s | %s | %s | %d of %d | %d of %d | %s |\n' "$1" "$2" "$3" "$ramp" "$speed" "$ok" "$total" \
    "$((ok + late))" "$total" "${fails%, }"
}

# FILTER=on: the `panda` preset as shipped (safety filter on) from the same starts, 120 s each:
# on how many starts, and on how many for more than 1 % of the ticks, the filter acts.
filtered() {
  local i=$1 q0 qd0 out
  read -r q0 qd0 <<< "$(draw "$i")"
  out=$($ctl simulate --preset panda --q0="$q0" --qd0="$qd0" --safety on --duration 120 --transient 0 --json 2>/dev/null) \
    || { echo "$i refused"; return; }
  echo "$i $(python3 -c 'import json, sys; print(json.load(sys.stdin)["safety_active_time"])' <<< "$out")"
}
export -f filtered
if [ "${FILTER:-off}" = on ]; then
  [ "$robot" = panda ] || { echo "FILTER=on runs the panda preset" >&2; exit 2; }
  seq 1 "$n" | xargs -P 2 -I{} bash -c "filtered {}" | sort -n > "$out/filter.txt"
  awk '$2 != "refused" { n++; if ($2 > 0) any++; if ($2 > 1.2) over++ }
    END { printf "filter on: %d starts; it acts on %d, on more than 1 %% of the ticks on %d\n", n, any, over }' \
    "$out/filter.txt"
  exit 0
fi

echo "| α | k_d | μ | task.ramp (s) | null_speed (rad/s) | periodic inside every limit | the same, but for the first 0.1 s's acceleration | failures (first limit broken, or too slow) |"
echo "|---|---|---|---|---|---|---|---|"
if [ "$robot" = xarm7 ]; then
  # The example's recipe (α = 20, μ = 1), the Panda's preset gains, and the xArm7's own
  # (docs/panda-study.md, "A second arm").
  variant 20.0 0.0 1.0 1.0
  variant 160.0 8.0 0.25 1.0 1.0
  variant 320.0 4.0 0.25 1.0 1.0
  exit 0
fi
if [ "${VARIANTS:-all}" = all ]; then
  variant 20.0 0.0 1.0
  variant 20.0 1.0 0.25
  variant 40.0 2.0 0.0
  variant 40.0 2.0 0.25
  variant 40.0 2.0 0.25 1.0
fi
variant 160.0 8.0 0.25 1.0
variant 160.0 8.0 0.25 1.0 1.0
variant 160.0 8.0 0.5 1.0 1.0
