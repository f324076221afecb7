"""Derives periodic height maps from photo-derived normal maps (CC0), for the unseen-content
accuracy suite. Not needed by the crate, its tests or the README's commands: the PNGs it writes
are committed under assets/height_maps/photo/.

Source: the npm package @pmndrs/assets 1.7.0 (CC0-1.0), folder normals/: 512x512 WebP normal
maps collected from https://github.com/emmelleppi/normal-maps (texture photographs turned into
normal maps). Get it with `npm pack @pmndrs/assets@1.7.0` and pass the .tgz.

Heights come from the normals by Frankot-Chellappa integration: the least-squares surface whose
gradient is closest to (-nx/nz, -ny/nz), solved in the Fourier domain, so the result is
periodic by construction (the map tiles). It is written as a 16-bit grey PNG, white high, the
range 0.5-99.5 percentile stretched to [0, 1].
Wavelengths longer than a third of the map are damped (see HIGH_PASS_CYCLES).

    pip install pillow numpy
    python3 tools/derive_height_maps.py pmndrs-assets-1.7.0.tgz assets/height_maps/photo
"""
import base64
import io
import sys
import tarfile
from pathlib import Path

import numpy as np
from PIL import Image

# name -> (normal map in the package, what the photograph shows)
CHOSEN = {
    "rock": ("0002", "rough rock face"),
    "bark": ("0011", "tree bark, fibrous vertical ridges"),
    "pebbles": ("0026", "pebbles set in mortar, granular"),
    "cracked": ("0024", "cracked dry ground, irregular cells"),
}
# Wavelengths longer than a third of the map are damped (a Gaussian high-pass): integrating a
# photograph's normals leaves a broad tilt and bowl (lighting gradients and non-integrable
# noise) that would dominate the range and is not relief a game would put in a height map.
HIGH_PASS_CYCLES = 3.0


def normal_map(tar: tarfile.TarFile, number: str) -> np.ndarray:
    text = tar.extractfile(f"package/normals/{number}.webp.js").read().decode()
    data = base64.b64decode(text.split("base64,")[1].rstrip("';\n "))
    rgb = np.asarray(Image.open(io.BytesIO(data)).convert("RGB"), dtype=np.float64) / 255.0
    n = rgb * 2.0 - 1.0
    # Tangent-space normal maps, OpenGL convention (green = +v, image rows run down): the
    # height gradient is (-nx/nz, +ny/nz) in (column, row) coordinates.
    nz = np.clip(n[..., 2], 0.2, 1.0)
    return np.stack([-n[..., 0] / nz, n[..., 1] / nz], axis=-1)


def frankot_chellappa(gradient: np.ndarray) -> np.ndarray:
    p, q = gradient[..., 0], gradient[..., 1]
    h, w = p.shape
    wx = 2.0 * np.pi * np.fft.fftfreq(w)[None, :]
    wy = 2.0 * np.pi * np.fft.fftfreq(h)[:, None]
    denominator = wx**2 + wy**2
    denominator[0, 0] = 1.0
    z = (-1j * wx * np.fft.fft2(p) - 1j * wy * np.fft.fft2(q)) / denominator
    z[0, 0] = 0.0
    cycles = np.sqrt((wx * w) ** 2 + (wy * h) ** 2) / (2.0 * np.pi)
    z *= 1.0 - np.exp(-((cycles / HIGH_PASS_CYCLES) ** 2))
    return np.real(np.fft.ifft2(z))


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit("usage: derive_height_maps.py pmndrs-assets-1.7.0.tgz OUT_DIR")
    out = Path(sys.argv[2])
    out.mkdir(parents=True, exist_ok=True)
    with tarfile.open(sys.argv[1]) as tar:
        for name, (number, what) in CHOSEN.items():
            z = frankot_chellappa(normal_map(tar, number))
            lo, hi = np.percentile(z, [0.5, 99.5])
            z = np.clip((z - lo) / (hi - lo), 0.0, 1.0)
            Image.fromarray((z * 65535.0 + 0.5).astype(np.uint16)).save(out / f"{name}.png")
            print(f"{name}: normals/{number}.webp ({what}) -> {out / (name + '.png')}")


if __name__ == "__main__":
    main()
