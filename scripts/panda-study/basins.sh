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
ctl=$PWD/target/release/chaosctl
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
    sed -e 's/^secondary = "centring"/secondary = "centring"\nnull_damping = 0.0/' \
      examples/own-urdf/xarm7.toml > "$out/panda.toml" ;;
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
  local cfg=$1 i=$2 q0 qd0 t60 t120
  read -r q0 qd0 <<< "$(draw "$i")"
  field() { grep -o "$1" <<< "$2" | head -1 | awk "{print \$$3}"; }
  if ! t60=$($ctl simulate --config "$cfg" --q0="$q0" --qd0="$qd0" --safety off --t-on 0 --duration 60 --transient 0 2>&1); then
    echo "$i refused"; return
  fi
  t120=$($ctl simulate --config "$cfg" --q0="$q0" --qd0="$qd0" --safety off --t-on 0 --duration 120 --transient 0)
  local r60 r120 sp ac je mg
  r60=$(field 'final [0-9.e+-]* rad/s' "$t60" 2)
  r120=$(field 'final [0-9.e+-]* rad/s' "$t120" 2)
  sp=$(field '([0-9.]*% of the limit)' "$t120" 1 | tr -d '(%')
  ac=$(field 'max [0-9.]*% of the acceleration' "$t120" 2 | tr -d '%')
  je=$(field '[0-9.]*% of the jerk' "$t120" 1 | tr -d '%')
  mg=$(field 'min [0-9.e+-]* rad to a position limit' "$t120" 2)
  # The acceleration peak of the first 0.1 s alone: the hand starts at rest on a moving path.
  local ac0 v
  ac0=$(field 'max [0-9.]*% of the acceleration' \
    "$($ctl simulate --config "$cfg" --q0="$q0" --qd0="$qd0" --safety off --t-on 0 --duration 0.1 --transient 0)" 2 | tr -d '%')
  v=$(awk -v a="$r60" -v b="$r120" -v s="$sp" -v c="$ac" -v c0="$ac0" -v j="$je" -v m="$mg" 'BEGIN {
    if (m <= 0) print "position"; else if (s > 100) print "speed";
    else if (c > 100 && c == c0) print "acceleration-at-start"; else if (c > 100) print "acceleration";
    else if (j > 100) print "jerk"; else if (a > 1e-3) print "slow60"; else if (b > 1e-6) print "slow120";
    else print "ok" }')
  echo "$i $v $r60 $r120 $sp $ac $je $mg"
}
export -f draw one
export ctl kind ready lo hi

variant() {
  local ramp=${4:-0} speed=${5:-0} name="a$1_kd$2_mu$3_ramp${4:-0}_speed${5:-0}" cfg
  cfg="$out/$name.toml"
  sed -e "s/^alpha = .*/alpha = $1/" -e "s/^null_damping = .*/null_damping = $2\nnull_speed = $speed/" \
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
  out=$($ctl simulate --preset panda --q0="$q0" --qd0="$qd0" --safety on --duration 120 --transient 0 2>&1) \
    || { echo "$i refused"; return; }
  echo "$i $(grep -o 'active [0-9.]* s' <<< "$out" | awk '{print $2}')"
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
