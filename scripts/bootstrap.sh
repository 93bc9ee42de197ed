#!/usr/bin/env bash
# Idempotent set-up of a fresh machine: system libraries, a local virtual environment, the
# project and its test dependencies. Called by `make demo` and `make test`; safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."

# System libraries: MuJoCo's offscreen renderer needs EGL (Mesa llvmpipe);
# rerun's headless screenshot needs Mesa's Vulkan driver; the SDF checker (scripts/sdf_check.cc)
# is built against libsdformat (Debian has no `gz sdf` command line tool); open3d does not import
# without libusb-1.0.so.0.
pkgs=(libegl1 libgl1 libglx-mesa0 libegl-mesa0 libgles2 mesa-vulkan-drivers libvulkan1 libsdformat-dev g++ pkg-config libusb-1.0-0)
missing=()
for p in "${pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo"; else
    echo "error: missing system packages ${missing[*]}; install them with apt-get (needs root)" >&2; exit 1; fi
  echo "installing system packages: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

PY=${PYTHON:-$(command -v python3.11 || command -v python3)}
if [ ! -x .venv/bin/python ]; then "$PY" -m venv .venv; fi
stamp=.venv/.installed-$(sha1sum pyproject.toml | cut -c1-12)
if [ ! -f "$stamp" ]; then
  .venv/bin/python -m pip install -q --upgrade pip
  # torch first, pinned, so that nothing pulls a CUDA build.
  .venv/bin/python -m pip install -q torch==2.13.0
  .venv/bin/python -m pip install -q -e '.[test]'
  rm -f .venv/.installed-*
  touch "$stamp"
fi

# The SDFormat checker, beside the interpreter, where exporters/sdf.py finds it: every scene.sdf
# written is then loaded by libsdformat. Rebuilt when its source changes.
checker=.venv/bin/scene-builder-sdf-check
if [ ! -x "$checker" ] || [ scripts/sdf_check.cc -nt "$checker" ]; then
  g++ -O1 -o "$checker" scripts/sdf_check.cc $(pkg-config --cflags --libs sdformat12)
fi

# The project's own modules compiled to bytecode, as pip does for an installed package: with
# PYTHONDONTWRITEBYTECODE set (as on some CI and container images) an editable install is
# otherwise compiled from source by every process, 0.2 s of each build. Up-to-date files are skipped.
.venv/bin/python -m compileall -q -j 0 scene_builder perception generation layout exporters
