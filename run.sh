#!/usr/bin/env bash
# Set-up and entry point for a fresh machine: installs the system libraries and a virtual
# environment when they are missing or out of date, then runs the requested job.
#   ./run.sh demo   exploration run on the default world (results under runs/)
#   ./run.sh test   the test suite
#   ./run.sh setup  only the set-up
#   ./run.sh lock   re-resolve requirements.lock from pyproject.toml (then run the full suite in a new venv)
set -euo pipefail
cd "$(dirname "$0")"
VENV=${EXPLORE_VENV:-.venv}
PY=${EXPLORE_PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
PIP_VERSION=26.3  # the installer itself is pinned too
UV_VERSION=0.13.9  # resolves the lock (./run.sh lock)

system_packages=(libusb-1.0-0 libgomp1 libgl1 graphviz chromium)
missing=()
for pkg in "${system_packages[@]}"; do
  dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if ((${#missing[@]})); then
  echo "installing system packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

[ -x "$VENV/bin/python" ] || "$PY" -m venv "$VENV"
pip=("$VENV/bin/python" -m pip --disable-pip-version-check)

if [ "${1:-}" = lock ]; then
  "${pip[@]}" install -q "uv==$UV_VERSION"
  "$VENV/bin/uv" pip compile pyproject.toml --extra test --extra rerun --python-version 3.11 \
    --python-platform x86_64-manylinux_2_35 --generate-hashes --no-header --upgrade -o requirements.lock.new
  { echo "# Exact versions of every runtime and test dependency (Linux x86_64, Python 3.11)."
    echo "# ./run.sh installs from this file. Refresh: ./run.sh lock, then EXPLORE_VENV=/tmp/fresh ./run.sh test"
    echo "# (the full suite in a new virtual environment); commit the new lock only when that is green."
    cat requirements.lock.new; } > requirements.lock
  rm requirements.lock.new
  echo "requirements.lock refreshed; now run the full suite in a new venv: EXPLORE_VENV=/tmp/fresh ./run.sh test"
  exit 0
fi

stamp="$VENV/.explore-installed"
want=$(cat pyproject.toml requirements.lock plugins/examples/*/pyproject.toml 2>/dev/null | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "installing Python packages into $VENV (from requirements.lock)"
  "${pip[@]}" install -q "pip==$PIP_VERSION"
  "${pip[@]}" install -q --require-hashes -r requirements.lock
  # the project itself, built with the locked setuptools (nothing resolved outside the lock)
  "${pip[@]}" install -q --no-deps --no-build-isolation -e .
  echo "$want" > "$stamp"
fi

export PYTHONWARNINGS=${PYTHONWARNINGS:-ignore::UserWarning:nanobind}
case "${1:-demo}" in
  demo) shift || true
        exec "$VENV/bin/explore" demo "$@" ;;
  test) shift || true
        exec "$VENV/bin/python" -m pytest "$@" ;;
  setup) exit 0 ;;
  *) echo "usage: ./run.sh demo|test|setup|lock" >&2; exit 2 ;;
esac
