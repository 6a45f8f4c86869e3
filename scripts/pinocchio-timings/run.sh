#!/usr/bin/env bash
# pinocchio's C++ timings on this machine, the anchor of `chaosd-bench compute`'s robot model
# table (bench/README.md, "Robot model").
#
# Usage: scripts/pinocchio-timings/run.sh [VENV] [OUT.json]
#   VENV      a Python venv with `pin` (pinocchio's wheel, which ships libpinocchio's headers and
#             libraries under site-packages/cmeel.prefix) [default: /tmp/pinvenv; created with
#             `python3 -m venv` + `pip install pin` if absent]
#   OUT.json  [default: out/pinocchio-timings.json, where `chaosd-bench compute` looks]
# Environment:
#   PREBUILT=1   time the wheel's own compiled algorithms (libpinocchio_default.so, baseline
#                x86-64) instead of compiling them from the headers with -march=native; the JSON
#                says which ("template_instantiation", "flags")
#   CORE=N       core to pin to [0]
#   ROUNDS, BATCHES, BATCH   the timing loop: rounds, batches in all, calls per batch [10, 10000,
#                100, as chaosd-bench compute times chaosd]; QUICK=1 makes it 2, 200, 100
#
# What it does: the venv's pinocchio reads robots/panda.urdf and writes the model in pinocchio's
# text serialisation; timings.cpp is compiled with g++ -O3 -march=native against the wheel's
# headers (Eigen's from the cmeel-eigen package, installed into the venv if missing; it is only a
# build dependency of the wheels), loads that model and times each operation at the tip
# panda_link8. A model filled by the wheel's URDF parser (compiled for baseline x86-64) crashes a
# program compiled with -march=native: the two disagree on Eigen's layout, hence the detour.
# The header-only compile takes 4-6 minutes on 2 cores (redone only when an input changed).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
venv="${1:-/tmp/pinvenv}"
out="${2:-$repo/out/pinocchio-timings.json}"
urdf="$repo/robots/panda.urdf"
tip=panda_link8

if [ ! -x "$venv/bin/python" ]; then
    echo "run.sh: creating $venv with pin (pinocchio)" >&2
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q pin
fi
site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
prefix="$site/cmeel.prefix"
if [ ! -d "$prefix/include/pinocchio" ]; then
    echo "run.sh: no pinocchio headers under $prefix (is pin installed in $venv?)" >&2
    exit 1
fi
if [ ! -f "$prefix/include/eigen3/Eigen/Core" ]; then
    echo "run.sh: installing cmeel-eigen (Eigen's headers) into $venv" >&2
    "$venv/bin/pip" install -q cmeel-eigen
fi
for f in include/eigen3/Eigen/Core include/boost/version.hpp lib/libboost_serialization.so \
    lib/libpinocchio_default.so; do
    [ -e "$prefix/$f" ] || { echo "run.sh: $prefix/$f is missing" >&2; exit 1; }
done
version="$("$venv/bin/python" -c 'import importlib.metadata as m; print(m.version("pin"))')"

build="$repo/target/pinocchio-timings"
mkdir -p "$build" "$(dirname "$out")"
model="$build/panda.model.txt"
"$venv/bin/python" - "$urdf" "$model" <<'EOF'
import sys
import pinocchio as pin
pin.buildModelFromUrdf(sys.argv[1]).saveToText(sys.argv[2])
EOF

# pinocchio's own compile definitions (its CMake targets' INTERFACE_COMPILE_DEFINITIONS).
defs="-DBOOST_MPL_LIMIT_LIST_SIZE=30 -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS -DBOOST_FUSION_INVOKE_MAX_ARITY=12"
libs="-lboost_serialization"
if [ "${PREBUILT:-0}" = 1 ]; then
    # The wheel's instantiations are compiled for baseline x86-64: so must the caller be.
    flags="-O3 -DNDEBUG -std=c++17"
    defs="$defs -DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION"
    libs="-lpinocchio_default $libs"
    exe="$build/timings-prebuilt"
else
    flags="-O3 -march=native -DNDEBUG -std=c++17"
    exe="$build/timings"
fi
# The compile is slow: redo it only when the source, the flags or the venv changed.
stamp="$exe.inputs"
inputs="$flags $defs $libs $prefix $version $(sha1sum "$here/timings.cpp" | cut -c1-40)"
if [ ! -x "$exe" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$inputs" ]; then
    echo "run.sh: g++ $flags, pin $version$([ "${PREBUILT:-0}" = 1 ] && echo ', its precompiled algorithms')" >&2
    # shellcheck disable=SC2086
    g++ $flags $defs -DTIMINGS_FLAGS="\"$flags\"" \
        -isystem "$prefix/include/eigen3" -isystem "$prefix/include" \
        "$here/timings.cpp" -o "$exe" \
        -L"$prefix/lib" -Wl,-rpath,"$prefix/lib" $libs
    echo "$inputs" >"$stamp"
fi

if [ "${QUICK:-0}" = 1 ]; then
    ROUNDS="${ROUNDS:-2}" BATCHES="${BATCHES:-200}"
fi
"$exe" "$model" "$tip" "$out" --urdf "robots/panda.urdf" \
    --core "${CORE:-0}" --rounds "${ROUNDS:-10}" --batches "${BATCHES:-10000}" --batch "${BATCH:-100}"
echo "run.sh: wrote $out" >&2
