#!/usr/bin/env bash
# Set up a machine for TacGen workflow: Debian's Mesa (EGL/OSMesa) for MuJoCo rendering on the
# CPU, then a virtual environment with the pinned torch (CPU build by default; TORCH=cuda for a
# GPU: tools/torch_build.py) and the project installed. Without TORCH, the build this
# environment was last set up with (remembered in VENV/.tacgen-torch), so a plain `make run`
# after `make setup TORCH=cuda` keeps CUDA. Writes no tracked file.
# Idempotent: a second run checks and returns in seconds.
# With --browser (make test), also Debian's Chromium and its driver: the report's browser test
# opens results/report.html in headless Chromium through Selenium.
#   usage: [TORCH=cpu|cuda|cuNNN|auto] tools/setup.sh [VENV_DIR] [--browser]   (default .venv)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=.venv
BROWSER=0
for arg in "$@"; do
  case "$arg" in
    --browser) BROWSER=1 ;;
    *) VENV=$arg ;;
  esac
done
PYTHON=${PYTHON:-python3}
started=$SECONDS

# 1. System packages for offscreen MuJoCo rendering (EGL through Mesa llvmpipe; OSMesa fallback),
#    and with --browser headless Chromium with its WebDriver.
APT_PKGS="libegl1 libegl-mesa0 libgl1-mesa-dri libglx-mesa0 libosmesa6"
[ "$BROWSER" = 1 ] && APT_PKGS="$APT_PKGS chromium chromium-driver"
missing=""
for p in $APT_PKGS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  echo "setup: installing Debian packages:$missing"
  if [ "$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi
  aptlog=$(mktemp)
  if ! { $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq \
      -o Dpkg::Use-Pty=0 --no-install-recommends $missing; } >"$aptlog" 2>&1; then
    cat "$aptlog"; echo "setup: apt-get failed (see above)" >&2; exit 1
  fi
  rm -f "$aptlog"
fi

# 2. Python environment. Which torch build, from where (tools/torch_build.py, tested offline):
#    TORCH=cpu the CPU build, from a local wheel folder (/opt/wheels) where it holds one, else
#    PyTorch's CPU index; TORCH=cuda (or cuNNN) a CUDA build, from a local CUDA wheel where there
#    is one, else the CUDA index; TORCH=auto cuda where an NVIDIA driver is loaded, else cpu;
#    no TORCH: the one remembered from this environment's last setup, else cpu.
#    constraints.txt pins torch's version.
if [ ! -x "$VENV/bin/python" ]; then
  echo "setup: creating $VENV"
  "$PYTHON" -m venv "$VENV"
fi
TORCH=$("$VENV/bin/python" tools/torch_build.py chosen --asked "${TORCH:-}" --venv "$VENV")
stamp="$VENV/.tacgen-installed"
want=$( (cat pyproject.toml constraints.txt tools/torch_build.py; echo "TORCH=$TORCH") | sha256sum | cut -c1-16)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setup: installing the project into $VENV (TORCH=$TORCH)"
  installed=$("$VENV/bin/python" tools/torch_build.py build 2>/dev/null || true)
  # uv (from PyPI) installs and byte-compiles on every core: on a 2-core machine about half
  # pip's time, most of which was pip compiling one file at a time. pip where uv cannot come.
  if "$VENV/bin/python" -m pip install -q uv >/dev/null 2>&1 && [ -x "$VENV/bin/uv" ]; then
    "$VENV/bin/python" tools/torch_build.py plan --run --torch "$TORCH" --installer uv \
      --uv "$VENV/bin/uv" --python "$VENV/bin/python" --installed "$installed"
  else
    echo "setup: uv unavailable; installing with pip"
    "$VENV/bin/python" -m pip install -q --upgrade pip
    "$VENV/bin/python" tools/torch_build.py plan --run --torch "$TORCH" --installer pip \
      --python "$VENV/bin/python" --installed "$installed"
  fi
  echo "$want" > "$stamp"
fi
# the build installed is the one asked for, else stop naming both; a CUDA build computes on
# the GPU (else stop naming the driver and the wheel's CUDA); then it is remembered
"$VENV/bin/python" tools/torch_build.py check --asked "$TORCH"
"$VENV/bin/python" tools/torch_build.py gpu-check
"$VENV/bin/python" tools/torch_build.py remember --venv "$VENV" "$TORCH"
# 3. The project's own modules byte-compiled: the editable install leaves them as source, and
#    every job's interpreter imports them (the preloaded interpreter holds third-party modules
#    only, tacgen_lib/runtime/preload.py); where PYTHONDONTWRITEBYTECODE is set nothing caches
#    them, so each job would compile what it imports again. Only files changed since are
#    compiled; an edited module's stale cache is ignored by Python (checked against its source).
"$VENV/bin/python" -m compileall -q tacgen_lib >/dev/null
"$VENV/bin/python" - <<'PY'
import sys
import torch
import mujoco, snakemake  # noqa: F401
build = f"cuda {torch.version.cuda}" if torch.version.cuda else "cpu"
print(f"setup: ok (python {sys.version.split()[0]}, torch {torch.__version__} [{build}], mujoco {mujoco.__version__})")
PY
echo "setup: done in $((SECONDS - started)) s"
