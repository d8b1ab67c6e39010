#!/usr/bin/env bash
# Set up everything wrinklepipe needs on a fresh Debian machine, then run a job.
#   bash ci/bootstrap.sh demo   # set up, then convert + validate the built-in demo character
#   bash ci/bootstrap.sh test   # set up, then lint, format check and the test suite
#   bash ci/bootstrap.sh setup  # set up only
# A rerun with nothing changed skips every install step (stamp files under .venv/).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
mode=${1:-setup}
shift || true

log() { printf '\033[1m[wrinklepipe setup]\033[0m %s\n' "$*" >&2; }

# 1. Debian packages for headless OpenGL (EGL + Mesa llvmpipe), the HLSL -> SPIR-V -> GLSL
#    compilers the shader tests use (glslang-tools, spirv-cross), chromium (the browser the
#    three.js viewer's tests drive, headless) and Node.js for the npm tools.
APT_PKGS="libegl1 libgl1 libgl1-mesa-dri glslang-tools spirv-cross chromium"
command -v npm >/dev/null 2>&1 || APT_PKGS="$APT_PKGS nodejs npm"
if ! command -v python3 >/dev/null 2>&1; then
  APT_PKGS="$APT_PKGS python3 python3-venv"
elif ! python3 -c "import ensurepip, venv" >/dev/null 2>&1; then
  APT_PKGS="$APT_PKGS python3-venv"  # Debian splits venv/ensurepip out of python3
fi
missing=""
for p in $APT_PKGS; do
  dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
if [ -n "$missing" ]; then
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  log "installing Debian packages:$missing"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
fi

# 2. The venv with the package and its test extras (reinstalled only when pyproject.toml changes).
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  log "creating .venv"
  "$PY" -m venv .venv
fi
stamp=.venv/.wrinklepipe-installed
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  log "installing wrinklepipe and its test extras into .venv"
  .venv/bin/python -m pip install -q --upgrade pip >/dev/null
  .venv/bin/python -m pip install -q -e ".[test]"
  echo "$want" > "$stamp"
fi
# The package's bytecode, as pip compiles what it installs (an editable install leaves the
# project's own modules uncompiled): with PYTHONDONTWRITEBYTECODE set, every `wrinklepipe` run
# and test process would compile the ~250 modules again (0.16 s of CPU each: `wrinklepipe
# convert --help` 1.27 -> 1.11 s). Up-to-date files are skipped; Python checks each .pyc
# against its source's mtime, so a stale one is never used.
.venv/bin/python -m compileall -q -j 0 wrinklepipe tests >/dev/null
# The BC4 encoder's numba kernels, compiled once into numba's cache beside the module (~12 s of
# CPU after a change to them, ~1 s otherwise): test workers and runs then load them instead of
# each compiling them.
.venv/bin/python -c "import numpy; from wrinklepipe.normals import bc4; bc4.encode_bc4(numpy.zeros((4, 4), numpy.uint8))"

# 3. npm tools in a project-local folder: the Khronos glTF-Validator, glTF-Transform's CLI
#    (an independent reader for `inspect`) and gltfpack (the real meshopt/quantization encoder
#    the ingest tests use), three.js (served by `wrinklepipe view`, no CDN) and playwright-core
#    (drives Debian's chromium in the viewer's tests; it never downloads a browser).
NPM_PKGS="gltf-validator @gltf-transform/cli gltfpack three playwright-core"
npm_missing=""
for p in $NPM_PKGS; do
  [ -f "tools/node/node_modules/$p/package.json" ] || npm_missing="$npm_missing $p"
done
if [ -n "$npm_missing" ]; then
  log "installing npm packages into tools/node:$npm_missing"
  mkdir -p tools/node
  PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 \
    npm install --silent --no-audit --no-fund --prefix tools/node $npm_missing >/dev/null
fi
# 4. Blender 5 as a Python module (PyPI bpy) in its own venv, .venv-blender: the tests import,
#    play and render every Blender export in it (tests/blender5.py). Not in .venv: bpy pins
#    numpy<2. bpy 5.0 is built for CPython 3.11 only: python3.11 when there is one, else python3
#    (3.11 on the CI image). Reinstalled only when BPY_SPEC changes.
BPY_SPEC="bpy>=5,<6"
BPY_PY=$(command -v python3.11 || command -v "$PY")
bstamp=.venv-blender/.wrinklepipe-installed
if [ ! -f "$bstamp" ] || [ "$(cat "$bstamp")" != "$BPY_SPEC" ]; then
  log "installing Blender 5 ($BPY_SPEC) into .venv-blender"
  [ -x .venv-blender/bin/python ] || "$BPY_PY" -m venv .venv-blender
  .venv-blender/bin/python -m pip install -q --upgrade pip >/dev/null
  .venv-blender/bin/python -m pip install -q "$BPY_SPEC"
  echo "$BPY_SPEC" > "$bstamp"
fi

export PATH="$ROOT/.venv/bin:$ROOT/tools/node/node_modules/.bin:$PATH"

case "$mode" in
  setup) log "ready: source .venv/bin/activate" ;;
  demo) exec wrinklepipe demo "$@" ;;
  test)
    ruff check .
    ruff format --check .
    exec python -m pytest -q -n 2 "$@"
    ;;
  *) echo "usage: bash ci/bootstrap.sh [setup|demo|test]" >&2; exit 2 ;;
esac
