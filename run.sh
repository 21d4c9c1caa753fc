#!/usr/bin/env bash
# Set-up and entry point for a fresh machine: installs the system libraries and a virtual
# environment when they are missing or out of date, then runs the requested job.
#   ./run.sh demo   exploration run on the default world (results under runs/)
#   ./run.sh test   the test suite
#   ./run.sh setup  only the set-up
set -euo pipefail
cd "$(dirname "$0")"
VENV=${EXPLORE_VENV:-.venv}
PY=${EXPLORE_PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3

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
stamp="$VENV/.explore-installed"
want=$(cat pyproject.toml plugins/examples/*/pyproject.toml 2>/dev/null | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "installing Python packages into $VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -e ".[test,rerun]"
  echo "$want" > "$stamp"
fi

export PYTHONWARNINGS=${PYTHONWARNINGS:-ignore::UserWarning:nanobind}
case "${1:-demo}" in
  demo) shift || true
        exec "$VENV/bin/explore" demo "$@" ;;
  test) shift || true
        exec "$VENV/bin/python" -m pytest "$@" ;;
  setup) exit 0 ;;
  *) echo "usage: ./run.sh demo|test|setup" >&2; exit 2 ;;
esac
