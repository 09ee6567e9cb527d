#!/usr/bin/env bash
# The Python package (python/, issue 40): builds the abi3 wheel with maturin in a virtual
# environment, sharing the workspace's target directory (the trainer compiled by `cargo test
# --release` is reused: only pyo3, numpy and the extension compile), installs it and runs pytest
# (python/tests) against the `cbd` binary and `cbd-fw-host` (the runtime's bit-for-bit reference).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
export CARGO_TARGET_DIR="$ROOT/target"
VENV="$ROOT/target/python-venv"
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
fi
"$VENV/bin/pip" install -q --disable-pip-version-check "maturin>=1.9.4,<2" pytest numpy pyyaml hypothesis
# The binaries `.ci/run` built before (cargo test --release, .ci/firmware.sh); built here only when
# missing, since a per-package build would compile the trainer again under other features.
[ -x target/release/cbd ] || cargo build -q --release -p cbd-trainer --bin cbd
[ -x target/debug/cbd-fw-host ] || cargo build -q -p cbd-fw-host
rm -rf target/wheels/cbd-*.whl
(cd python && "$VENV/bin/maturin" build --quiet --release -o "$ROOT/target/wheels")
"$VENV/bin/pip" install -q --disable-pip-version-check --force-reinstall --no-deps target/wheels/cbd-*.whl
# From outside the source tree, so that `import cbd` is the installed wheel.
cd "$ROOT/target"
"$VENV/bin/python" -m pytest -q -p no:cacheprovider --durations=5 "$ROOT/python/tests"
