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

bash "$root/scripts/setup_deps.sh" python3-skimage

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
