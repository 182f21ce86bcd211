#!/usr/bin/env bash
# Copies a few CC0 sample images of scikit-image (Debian package python3-skimage) into
# datasets/textures/ (git-ignored), for scene YAMLs that use image textures, e.g.
#   texture: {file: textures/brick.png}          (paths are relative to the YAML file)
# Installs python3-skimage with apt-get when it is missing (as root, or through sudo).
#   bash scripts/fetch_textures.sh [DEST]        # default DEST: datasets/textures
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
dest="${1:-$root/datasets/textures}"
images=(camera astronaut brick grass gravel text moon coins)

if ! dpkg-query -W -f='${Status}' python3-skimage 2>/dev/null | grep -q "install ok installed"; then
  if [ "$(id -u)" -eq 0 ]; then
    SUDO=()
  elif command -v sudo >/dev/null 2>&1; then
    SUDO=(sudo)
  else
    echo "fetch_textures: python3-skimage is missing and this is not root and there is no sudo; as root run:" >&2
    echo "  apt-get install --no-install-recommends python3-skimage" >&2
    exit 1
  fi
  echo "fetch_textures: installing python3-skimage"
  export DEBIAN_FRONTEND=noninteractive
  "${SUDO[@]}" apt-get update -qq
  "${SUDO[@]}" apt-get install -y -qq --no-install-recommends python3-skimage >/dev/null
fi

# The package's data folder (skimage/data/*.png), found from its file list (no Python import).
src="$(dpkg -L python3-skimage | grep -E '/skimage/data/camera\.png$' | head -n 1 | xargs -r dirname)"
if [ -z "$src" ] || [ ! -d "$src" ]; then
  echo "fetch_textures: cannot find skimage/data in python3-skimage's files" >&2
  exit 1
fi

mkdir -p "$dest"
copied=0
for name in "${images[@]}"; do
  if [ -f "$src/$name.png" ]; then
    cp "$src/$name.png" "$dest/$name.png"
    copied=$((copied + 1))
  else
    echo "fetch_textures: $name.png not in $src (skipped)" >&2
  fi
done
echo "fetch_textures: copied $copied image(s) from $src to $dest"
