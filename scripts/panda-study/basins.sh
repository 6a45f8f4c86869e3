#!/usr/bin/env bash
# The basin study of docs/panda-study.md, made with `chaosctl starts`: N random starts (seed 1,
# the same on every machine), the law alone (filter off, feedback from t = 0), for the preset
# and the variants of the gain study. A start succeeds when its period residual is ≤ 1e-3 rad/s
# over 40-60 s and ≤ 1e-6 over 100-120 s, and every joint stays inside its position, speed,
# acceleration and jerk limits for all 120 s. Starts whose circle is out of reach are refused by
# the config check and left out.
# Usage: [ROBOT=panda|xarm7] [VARIANTS=all|new] [FILTER=on] [PLANT=torque] scripts/panda-study/basins.sh [near|box] [N] [out-dir]
#   near: each joint within ±0.5 rad of the ready pose, rates within ±0.1 rad/s;
#   box:  anywhere in the joint box (10 % in from each limit), rates within ±0.2 rad/s.
# The last variants start the path from rest (task.ramp = 1 s); the ones with null_speed cap the
# centring pull's velocity (law.null_speed), the `panda` preset. VARIANTS=new runs the α = 160 rows.
# FILTER=on: the `panda` preset as shipped (safety filter on): on how many starts the filter acts.
# PLANT=torque: the `panda` preset in torque mode against the rigid-body arm, exact, 20 % heavier
# with 1 kg at the tip, and that with friction and sensor noise too.
# Needs a release build (cargo build --release -p client). About 15 s per row for N = 100 on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
kind=${1:-near}
n=${2:-100}
robot=${ROBOT:-panda}
out=${3:-out/$robot-basins-$kind}
mkdir -p "$out"
ctl=${CHAOSD_BIN:-$PWD/target/release}/chaosctl
case $robot in
  panda) $ctl config --preset panda-paper > "$out/base.toml" ;;
  xarm7) cp examples/own-urdf/xarm7.toml "$out/base.toml" ;;
  *) echo "ROBOT=$robot: panda or xarm7" >&2; exit 2 ;;
esac

# study NAME CONFIG [FLAGS…]: the starts of this draw from CONFIG, into $out/NAME.csv.
study() {
  local name=$1 cfg=$2
  shift 2
  $ctl starts --config "$cfg" --draw "$kind" --count "$n" --seed 1 --output "$out/$name" "$@" > "$out/$name.txt"
}

# row CSV: "periodic of run | the same but for the start's acceleration | failures" from the
# verdicts (column 2) and, for the starts whose only fault is the first 0.1 s's acceleration,
# their residual and tracking columns.
row() {
  awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) col[$i] = i; next }
    $2 == "refused" { next }
    { run++ }
    $2 == "periodic" { ok++; next }
    { fail[$2]++ }
    $2 == "acceleration at the start" && $col["residual_60s"] <= 1e-3 && $col["residual_120s"] <= 1e-6 && $col["tracking_max"] <= 5e-3 { late++ }
    END {
      f = ""; for (k in fail) f = f (f == "" ? "" : ", ") k " " fail[k];
      printf "%d of %d | %d of %d | %s", ok, run, ok + late, run, (f == "" ? "none" : f)
    }' "$1"
}

variant() {
  local ramp=${4:-0} speed=${5:-0} name="a$1_kd$2_mu$3_ramp${4:-0}_speed${5:-0}" cfg
  cfg="$out/$name.toml"
  # A zero null_damping or null_speed is left out of the printed file: both are added after
  # [law], not substituted.
  sed -e "s/^alpha = .*/alpha = $1/" -e "/^null_damping = /d" -e "/^null_speed = /d" \
    -e "/^\[law\]/a null_damping = $2\nnull_speed = $speed" \
    -e "s/^mu = .*/mu = $3/" -e "s/^period = 2.0/period = 2.0\nramp = $ramp/" \
    "$out/base.toml" > "$cfg"
  study "$name" "$cfg" --safety off --t-on 0
  printf '| %s | %s | %s | %s | %s | %s |\n' "$1" "$2" "$3" "$ramp" "$speed" "$(row "$out/$name.csv")"
}

if [ "${FILTER:-off}" = on ]; then
  [ "$robot" = panda ] || { echo "FILTER=on runs the panda preset" >&2; exit 2; }
  $ctl config --preset panda > "$out/panda.toml"
  study filter "$out/panda.toml"
  awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) col[$i] = i; next }
    $2 != "refused" { run++; a = $col["filter_active"]; if (a > 0) any++; if (a > 0.01) over++; if ($2 == "periodic") ok++ }
    END { printf "filter on: %d starts, periodic inside every limit %d; the filter acts on %d, on more than 1 %% of the run on %d\n", run, ok, any, over }' \
    "$out/filter.csv"
  exit 0
fi

if [ "${PLANT:-}" = torque ]; then
  [ "$robot" = panda ] || { echo "PLANT=torque runs the panda preset" >&2; exit 2; }
  $ctl config --preset panda > "$out/panda.toml"
  echo "| plant | periodic inside every limit | the same, but for the first 0.1 s's acceleration | failures |"
  echo "|---|---|---|---|"
  for plant in exact heavy heavy-friction-noise; do
    cfg="$out/torque-$plant.toml"
    cp "$out/panda.toml" "$cfg"
    case $plant in
      heavy) printf '\n[plant.rigid_body]\nmass_scale = 1.2\npayload = 1.0\n' >> "$cfg" ;;
      heavy-friction-noise)
        printf '\n[plant.rigid_body]\nmass_scale = 1.2\npayload = 1.0\nviscous = [0.1, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05]\ncoulomb = [0.3, 0.3, 0.3, 0.3, 0.2, 0.2, 0.2]\nnoise_q = 1e-5\nnoise_qd = 1e-3\nnoise_tau = 0.05\n' >> "$cfg" ;;
    esac
    study "torque-$plant" "$cfg" --safety off --t-on 0 --plant rigid-body --mode torque
    printf '| %s | %s |\n' "$plant" "$(row "$out/torque-$plant.csv")"
  done
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
