#!/usr/bin/env bash
# Install every Debian package needlehex needs: build, tests, plots, pictures
# (xvfb: a virtual display for tools/render.py; ffmpeg: its MP4; elastix: its
# transformix applies the exported displacement fields in tests/nifti_field.py;
# valgrind: callgrind's instruction counts, docs/performance.md).
# Idempotent; run as root (or with sudo available).
set -euo pipefail
pkgs=(
  build-essential cmake pkg-config clang-format clang libclang-rt-14-dev
  libsuitesparse-dev libopenblas-dev liblapacke-dev
  libyaml-dev libhdf5-dev zlib1g-dev libnifti2-dev libjson-c-dev
  python3 python3-numpy python3-matplotlib python3-vtk9 python3-meshio python3-h5py python3-nibabel python3-scipy
  python3-distributed python3-yaml
  elastix
  xvfb ffmpeg git valgrind
)
sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
