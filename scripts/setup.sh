#!/usr/bin/env bash
# One entry point for a fresh machine:
#
#   bash scripts/setup.sh quick   # set up, then run the main job on a small default and write reports/quick/ (the committed reports/ stay)
#   bash scripts/setup.sh test    # set up, then run the test suite and build the docs site (tox)
#   bash scripts/setup.sh         # set up only
#
# Set-up = (1) a Vulkan device SAPIEN accepts (on a GPU-less Debian 12 that is Mesa >= 24.3 from
# bookworm-backports), (2) tox, (3) the Meta-World workers' environment .venv-metaworld and the EGL
# libraries MuJoCo renders with (metaworld pins a MuJoCo the project's mink refuses, see
# awda_bench/runtimes.py), (4) the project's environment .venv (owned by tox, shared by all tox
# envs so torch is installed once). Every step is idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
what="${1:-setup}"
PY="${PYTHON:-python3}"

log() { printf '[setup] %s\n' "$*"; }

mesa_version() {
  dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null | sed -E 's/^[0-9]+://; s/[-~+].*//' || true
}

version_ge() { [ "$(printf '%s\n%s\n' "$2" "$1" | sort -V | head -n1)" = "$2" ]; }

ensure_renderer() {
  if [ -n "${AWDA_SKIP_RENDERER_SETUP:-}" ]; then log "renderer set-up skipped (AWDA_SKIP_RENDERER_SETUP)"; return; fi
  if command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; then
    log "NVIDIA GPU present: SAPIEN renders on it"; return
  fi
  local have; have="$(mesa_version)"
  if [ -n "$have" ] && version_ge "$have" 24.3; then
    log "Mesa lavapipe $have present (>= 24.3)"; return
  fi
  local id="" codename=""
  if [ -r /etc/os-release ]; then . /etc/os-release; id="${ID:-}"; codename="${VERSION_CODENAME:-}"; fi
  local sudo=""
  if [ "$(id -u)" != 0 ]; then
    if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then sudo="sudo -n"; fi
  fi
  if [ "$id" = debian ] && [ "$codename" = bookworm ]; then
    if [ "$(id -u)" != 0 ] && [ -z "$sudo" ]; then
      log "ERROR: SAPIEN needs Mesa >= 24.3 (have '${have:-none}'). As root run:"
      log "  printf 'Types: deb\nURIs: http://deb.debian.org/debian\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' > /etc/apt/sources.list.d/bookworm-backports.sources && apt-get update && apt-get install -y -t bookworm-backports mesa-vulkan-drivers libvulkan1"
      exit 1
    fi
    log "installing mesa-vulkan-drivers from bookworm-backports (Debian 12's Mesa ${have:-none} is too old for SAPIEN)"
    if ! grep -rqs bookworm-backports /etc/apt/sources.list /etc/apt/sources.list.d/; then
      printf 'Types: deb\nURIs: http://deb.debian.org/debian\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
        | $sudo tee /etc/apt/sources.list.d/bookworm-backports.sources >/dev/null
    fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq -t bookworm-backports mesa-vulkan-drivers libvulkan1 >/dev/null
    have="$(mesa_version)"
    if [ -z "$have" ] || ! version_ge "$have" 24.3; then
      log "ERROR: after installing from bookworm-backports Mesa is '${have:-none}', still older than 24.3"
      exit 1
    fi
    log "Mesa $have installed"
  elif [ "$id" = ubuntu ] || [ "$id" = debian ]; then
    if [ "$(id -u)" = 0 ] || [ -n "$sudo" ]; then
      DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null || true
    fi
    have="$(mesa_version)"
    if [ -z "$have" ] || ! version_ge "$have" 24.3; then
      log "ERROR: SAPIEN needs a GPU driver or Mesa >= 24.3 (have '${have:-none}'): install mesa-vulkan-drivers >= 24.3 (Ubuntu >= 24.04 ships it)"
      exit 1
    fi
  else
    log "WARNING: cannot check the Vulkan driver on '$id'; 'python -m awda_bench doctor' will tell"
  fi
}

TOX_REQS=('tox>=4.11' 'tox-ignore-env-name-mismatch>=0.2')

ensure_tox() {
  # the plugin lets every tox env reuse the one .venv (torch is installed once)
  if "$PY" -m tox --version >/dev/null 2>&1 && "$PY" -c 'import tox_ignore_env_name_mismatch' 2>/dev/null; then
    return
  fi
  log "installing ${TOX_REQS[*]} for $PY"
  "$PY" -m pip install -q --disable-pip-version-check "${TOX_REQS[@]}" 2>/dev/null \
    || "$PY" -m pip install -q --user --disable-pip-version-check "${TOX_REQS[@]}"
}

has_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }

ensure_egl() {
  # MuJoCo renders headless through EGL (Mesa's software renderer without a GPU)
  if has_lib 'libEGL.so.1' && has_lib 'libEGL_mesa.so.0'; then return; fi
  local sudo=""
  if [ "$(id -u)" != 0 ]; then
    if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then sudo="sudo -n"; else
      log "ERROR: Meta-World renders through EGL: as root run apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri"
      exit 1
    fi
  fi
  local target=()
  if grep -rqs bookworm-backports /etc/apt/sources.list /etc/apt/sources.list.d/; then target=(-t bookworm-backports); fi
  log "installing the EGL libraries MuJoCo renders with"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${target[@]}" libegl1 libegl-mesa0 libgl1-mesa-dri >/dev/null
}

MW_VENV=.venv-metaworld
MW_REQS=requirements-metaworld.txt

ensure_metaworld_venv() {
  if [ -n "${AWDA_SKIP_METAWORLD_SETUP:-}" ]; then log "Meta-World environment skipped (AWDA_SKIP_METAWORLD_SETUP)"; return; fi
  ensure_egl
  local want; want="$(sha256sum "$MW_REQS" | cut -d' ' -f1)"
  if [ -x "$MW_VENV/bin/python" ] && [ "$(cat "$MW_VENV/.requirements.sha256" 2>/dev/null)" = "$want" ]; then
    log "$MW_VENV present"; return
  fi
  log "making $MW_VENV (metaworld and its MuJoCo; see $MW_REQS)"
  if [ ! -x "$MW_VENV/bin/python" ]; then
    # the standard library's venv first: virtualenv >= 21 also writes a PEP-832 ".venv" redirect
    # file beside pyproject.toml, which would stand where tox makes the project's .venv
    if ! "$PY" -m venv "$MW_VENV" 2>/dev/null; then
      rm -rf "$MW_VENV"
      "$PY" -m virtualenv -q --no-venv-redirect "$MW_VENV" 2>/dev/null || "$PY" -m virtualenv -q "$MW_VENV"
    fi
  fi
  "$MW_VENV/bin/python" -m pip install -q --disable-pip-version-check -r "$MW_REQS"
  MUJOCO_GL=egl "$MW_VENV/bin/python" -c 'import metaworld, mujoco' >/dev/null
  echo "$want" > "$MW_VENV/.requirements.sha256"
}

ensure_renderer
ensure_tox
ensure_metaworld_venv
case "$what" in
  setup) "$PY" -m tox run -e py --notest ;;
  quick) "$PY" -m tox run -e quick ;;
  test)  "$PY" -m tox run -e py,smoke,lint,docs ;;
  *) echo "usage: bash scripts/setup.sh [setup|quick|test]" >&2; exit 2 ;;
esac
