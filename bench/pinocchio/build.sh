#!/usr/bin/env bash
# Builds the Pinocchio harness of `alnlab bench sim --pinocchio` into $1
# (default target/pinocchio-aba) against the Pinocchio of PyPI's `pin`
# wheel (headers, libraries, Boost) and Debian's Eigen and urdfdom headers
# (libeigen3-dev, liburdfdom-headers-dev), with the instruction set the
# workspace compiles for (x86-64-v2) and -O3. Pinocchio's joint variant has
# 25 types, more than Boost.MPL's preprocessed lists hold: its own build
# raises the limit the same way. About a minute.
#
#   PYTHON=target/xtask/venv/bin/python bash bench/pinocchio/build.sh
set -euo pipefail
out=${1:-target/pinocchio-aba}
python=${PYTHON:-target/xtask/venv/bin/python}
prefix=$("$python" - <<'PY'
import sys, pathlib
for p in sys.path:
    c = pathlib.Path(p) / "cmeel.prefix"
    if (c / "include/pinocchio").is_dir():
        print(c)
        break
else:
    sys.exit("no Pinocchio headers: pip install pin")
PY
)
here=$(dirname "$0")
g++ -std=c++17 -O3 -DNDEBUG -march=x86-64-v2 \
    -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS -DBOOST_MPL_LIMIT_LIST_SIZE=30 \
    -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 \
    -I"$prefix/include" -I/usr/include/eigen3 \
    "$here/aba.cpp" -o "$out" \
    -L"$prefix/lib" -Wl,-rpath,"$prefix/lib" \
    -lpinocchio_default -lpinocchio_parsers
echo "built $out against $prefix"
