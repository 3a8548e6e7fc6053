#!/usr/bin/env bash
# Set up everything the tests use and run the whole suite (quick and slow real-data tests).
#   Debian packages: Mesa EGL (GL backend and fidelity renders), Node.js (Khronos glTF-Validator)
#   Python: lodconvert[test] in .venv;  npm: gltf-validator in ./node_modules
# Extra arguments go to pytest, e.g. scripts/test.sh -m 'not slow' for the quick suite only.
source "$(dirname "$0")/_env.sh"
apt_install libegl1 libgl1 libgl1-mesa-dri
command -v npm >/dev/null || apt_install nodejs npm
make_venv "[test]"
[ -d node_modules/gltf-validator ] || npm install --no-save --no-audit --no-fund --silent --prefix . gltf-validator@2.0.0-dev.3.10
export LODCONVERT_REQUIRE_VALIDATORS=1 LODCONVERT_REQUIRE_GL=1
set +e
if [ $# -eq 0 ]; then set -- -m "slow or not slow"; fi
.venv/bin/python -m pytest "$@"
status=$?
[ $status -eq 5 ] && { echo "pytest collected no tests" >&2; exit 1; }
exit $status
