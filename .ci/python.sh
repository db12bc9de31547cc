#!/usr/bin/env bash
# CI, Python part: `pip install .` into a fresh virtual environment under target/, then the pytest suite
# (python/tests), which compares the package with the CLI and runs the Ray command on a local Ray.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
VENV=target/ci-venv
rm -rf "$VENV"
"$PY" -m venv "$VENV"
"$VENV/bin/pip" install --quiet --upgrade pip
# Pinned test dependencies (Ray Data and its Arrow): one resolver run, wheels only.
"$VENV/bin/pip" install --quiet --only-binary=:all: \
    "numpy==2.4.6" "pytest==9.2.0" "ray[data]==2.60.0" "pyarrow==26.0.1"
# The package itself, built by maturin (release profile: CI's one release build, in target/ like cargo's).
"$VENV/bin/pip" install --quiet .
export RANGESEG_REQUIRE_RAY=1
# The CLI the tests compare with: the one `cargo test` built just before (else conftest builds it with cargo).
if [ -x target/debug/rangeseg ]; then export RANGESEG_CLI="$PWD/target/debug/rangeseg"; fi
set +e
(cd python/tests && ../../"$VENV/bin/python" -m pytest -q -p no:cacheprovider .)
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
    echo "pytest collected no tests: failing" >&2
    exit 1
fi
exit "$rc"
