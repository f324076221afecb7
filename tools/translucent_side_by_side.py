#!/usr/bin/env python3
"""Pictures side by side for docs/translucent.md: each row a reference and the plugin's picture
(linear EXRs of one size, as `translucent_accuracy` writes them), both scaled by the row's
reference (its 99th percentile of the pixels it covers maps to white), sRGB-encoded, and a
third panel with the ratio plugin / reference of their channel sums: white where they agree,
red where the plugin is brighter, blue where it is darker (saturating at 2× and 0×).

    python3 tools/translucent_side_by_side.py --out docs/images/translucent_bunny.png \\
        tests/data/translucent/bunny_skin1_front_mitsuba.exr \\
        out/translucent_accuracy/plugin_bunny_skin1_front_patches_scaleddipole_1000.exr ...

Needs `mitsuba` and `numpy` (PyPI), as the reference renderer does; not needed by the crate.
"""

import argparse
import sys


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("pictures", nargs="+", help="reference.exr plugin.exr, a pair per row")
    parser.add_argument("--out", required=True, help="the PNG to write")
    parser.add_argument("--zoom", type=int, default=3, help="pixels per picture pixel")
    args = parser.parse_args()
    if len(args.pictures) % 2 != 0:
        parser.error("pictures come in pairs: a reference, then the plugin's")
    if args.zoom < 1:
        parser.error("--zoom must be at least 1")

    import mitsuba as mi
    import numpy as np

    mi.set_variant("scalar_rgb")

    def read(path):
        try:
            return np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]
        except Exception as e:  # Mitsuba raises its own exception types.
            sys.exit(f"error: cannot read {path}: {e}")

    rows = []
    for reference_path, plugin_path in zip(args.pictures[::2], args.pictures[1::2]):
        reference, plugin = read(reference_path), read(plugin_path)
        if reference.shape != plugin.shape:
            sys.exit(f"error: {reference_path} and {plugin_path} differ in size")
        covered = reference.sum(-1) > 0
        peak = np.percentile(reference[covered], 99) if covered.any() else 1.0

        def encode(x):
            c = np.clip(x / max(peak, 1e-12), 0.0, 1.0)
            s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
            return (s * 255.0 + 0.5).astype(np.uint8)

        ratio = np.clip(plugin.sum(-1) / np.maximum(reference.sum(-1), 1e-12), 0.0, 2.0)
        brighter = np.clip(ratio - 1.0, 0.0, 1.0)
        darker = np.clip(1.0 - ratio, 0.0, 1.0)
        panel = np.stack([1.0 - darker, 1.0 - brighter - darker, 1.0 - brighter], -1)
        panel[~covered] = 0.0
        rows.append(np.concatenate(
            [encode(reference), encode(plugin), (panel * 255.0 + 0.5).astype(np.uint8)], 1))
    image = np.concatenate(rows, 0)
    image = np.repeat(np.repeat(image, args.zoom, 0), args.zoom, 1)
    mi.Bitmap(np.ascontiguousarray(image)).write(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    sys.exit(main())
