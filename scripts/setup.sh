#!/usr/bin/env bash
# One-time setup of a checkout (idempotent, fast when already done):
#   1. a virtual environment at .venv (Python >= 3.11),
#   2. torch: a CPU build where there is no NVIDIA GPU (never a multi-GB CUDA download there),
#   3. this project, its test extras and Ray (workers.backend=ray; its tests), editable,
#   4. a Vulkan driver SAPIEN can use. Without a GPU driver that is Mesa's lavapipe >= 24.3;
#      on Debian 12 it comes from bookworm-backports, elsewhere we say what to install,
#   5. where there is an NVIDIA GPU: SAPIEN's PhysX GPU library (it would otherwise download it
#      with no time limit the first time GPU physics starts); without network it says so and goes on,
#   (the compiled fabric step, controller.fabric.compiled, a speed lever no preset uses, is built by
#   the first run that asks for it, about a minute with g++; `python -m realize.cli.prebuild` builds it ahead)
# Re-run it any time; it only does what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=.venv
PY=${PYTHON:-python3}
STAMP=$VENV/.realize-setup
TORCH_VERSION=2.13.0  # the same torch on CPU and CUDA machines

say() { printf '[setup] %s\n' "$*"; }
has_gpu() { command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; }
# 5. SAPIEN's PhysX GPU library, where there is a GPU (checked on every run: cheap, and a fetch
#    that failed offline is tried again once there is network)
physx_gpu() {
  has_gpu || return 0
  "$VENV/bin/python" -m realize.physx_gpu >/dev/null 2>&1 && return 0
  "$VENV/bin/python" -m realize.physx_gpu --fetch --timeout 300 \
    || say "warning: no PhysX GPU library: device=cuda will refuse to start until it is there (see above)"
}

want=$(cat pyproject.toml scripts/setup.sh | sha256sum | cut -c1-16)
if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$want" ] && [ -x "$VENV/bin/python" ]; then
  physx_gpu
  exit 0
fi

# 1. virtual environment
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' \
    || { echo "[setup] error: Python >= 3.11 is required ($PY is $($PY --version 2>&1)); set PYTHON=python3.11" >&2; exit 1; }
  say "creating $VENV"
  "$PY" -m venv "$VENV"
fi
PIP="$VENV/bin/python -m pip"

# 2. torch
if ! "$VENV/bin/python" -c 'import torch' 2>/dev/null; then
  if has_gpu; then
    say "NVIDIA GPU found: installing torch $TORCH_VERSION with CUDA"
    $PIP install -q "torch==$TORCH_VERSION" \
      || { echo "[setup] error: could not install torch==$TORCH_VERSION (CUDA build from the package index)" >&2; exit 1; }
  else
    say "no NVIDIA GPU: installing a CPU build of torch"
    # a local CPU wheel (torch==X+cpu) is preferred; a configured CPU index works too
    $PIP install -q "torch==$TORCH_VERSION+cpu" 2>/dev/null || $PIP install -q "torch==$TORCH_VERSION" \
      || { echo "[setup] error: could not install a CPU build of torch. Configure pip with a CPU wheel index (or a local wheel) and re-run." >&2; exit 1; }
  fi
fi

# 3. the project
say "installing realize (editable) with its test, ray and docs extras"
$PIP install -q -e ".[test,ray,docs]" 2>&1 | grep -v -i "is ignored" || true
"$VENV/bin/python" -c 'import realize, envs, mani_skill, sapien, hydra, rerun, ray, optuna, hydra_plugins.hydra_optuna_sweeper, mkdocs, mkdocstrings' \
  || { echo "[setup] error: the package install failed (see pip output above)" >&2; exit 1; }

# 4. Vulkan for SAPIEN
vk_ok() { "$VENV/bin/python" - <<'PY' 2>/dev/null
import warnings; warnings.filterwarnings("ignore")
import sapien.render
sapien.render.RenderSystem()
PY
}
if vk_ok; then
  say "SAPIEN found a Vulkan rendering device"
else
  . /etc/os-release 2>/dev/null || true
  if [ "${ID:-}" = debian ] && [ "${VERSION_CODENAME:-}" = bookworm ]; then
    say "no Vulkan device: installing Mesa's lavapipe from bookworm-backports (needs Mesa >= 24.3)"
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
    src=/etc/apt/sources.list.d/debian.sources
    uri=$(awk '/^URIs:/{print $2; exit}' "$src" 2>/dev/null || true)
    [ -n "$uri" ] || uri=$(awk '/^deb /{print $2; exit}' /etc/apt/sources.list 2>/dev/null || true)
    [ -n "$uri" ] || { echo "[setup] error: cannot find the Debian mirror in the apt sources; add bookworm-backports and install mesa-vulkan-drivers from it" >&2; exit 1; }
    key=/usr/share/keyrings/debian-archive-keyring.gpg
    printf 'Types: deb\nURIs: %s\nSuites: bookworm-backports\nComponents: main\nSigned-By: %s\n' "$uri" "$key" \
      | $SUDO tee /etc/apt/sources.list.d/realize-backports.sources >/dev/null
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq -t bookworm-backports mesa-vulkan-drivers libvulkan1 >/dev/null
    vk_ok || { echo "[setup] error: SAPIEN still finds no Vulkan device after installing lavapipe" >&2; exit 1; }
    say "Vulkan (lavapipe) works"
  else
    cat >&2 <<MSG
[setup] error: SAPIEN finds no Vulkan rendering device ("failed to find a rendering device").
  With an NVIDIA GPU: install the NVIDIA driver with its Vulkan ICD (libnvidia-gl / nvidia-vulkan-icd).
  Without a GPU: install Mesa's Vulkan drivers (lavapipe) version 24.3 or newer
  (Debian/Ubuntu package: mesa-vulkan-drivers; Fedora: mesa-vulkan-drivers) and libvulkan1, then re-run.
MSG
    exit 1
  fi
fi
physx_gpu
echo "$want" > "$STAMP"
say "done"
