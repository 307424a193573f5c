#!/usr/bin/env bash
# Installs the system packages alphasurf needs to build and run on a fresh Debian 12 machine:
# the Vulkan loader, Mesa's lavapipe (CPU Vulkan driver), the validation layers, and the static
# shaderc/glslang/SPIRV-Tools libraries that build.rs links (see .cargo/config.toml).
# Skips apt entirely when everything is already there. Needs root (or sudo) for apt-get.
set -euo pipefail
pkgs=(libvulkan1 mesa-vulkan-drivers vulkan-validationlayers libshaderc-dev glslang-dev spirv-tools)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
command -v cargo >/dev/null || { echo "setup: cargo not found (install Rust with rustup)"; exit 1; }
echo "setup: system packages present"
