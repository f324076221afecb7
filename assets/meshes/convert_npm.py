#!/usr/bin/env python3
"""Converts the public-domain meshes of the npm packages `teapot` (1.0.0) and `bunny` (1.0.1)
into the OBJ files next to this script: centred, scaled so that the longest side of the
bounding box is 1.6 (the gallery's spheres have diameter 1.6), vertices and triangles only
(the gallery computes normals and UVs).

    npm pack teapot@1.0.0 bunny@1.0.1   # or download the tarballs from registry.npmjs.org
    tar xzf teapot-1.0.0.tgz && mv package teapot
    tar xzf bunny-1.0.1.tgz && mv package bunny
    python3 convert_npm.py teapot/teapot.js bunny/index.js
"""
import json
import re
import sys
from pathlib import Path

SOURCES = {
    "teapot": "npm package `teapot` 1.0.0 (Mikola Lysenko, public domain): the Utah teapot "
    "(Martin Newell, 1975)",
    "bunny": "npm package `bunny` 1.0.1 (Mikola Lysenko, public domain): the Stanford bunny "
    "(Stanford 3D Scanning Repository), decimated",
}


def convert(name: str, js_path: str) -> None:
    src = Path(js_path).read_text()
    positions = json.loads(re.search(r"exports\.positions\s*=\s*(\[.*?\]\])", src, re.S).group(1))
    cells = json.loads(re.search(r"exports\.cells\s*=\s*(\[.*?\]\])", src, re.S).group(1))
    lo = [min(p[i] for p in positions) for i in range(3)]
    hi = [max(p[i] for p in positions) for i in range(3)]
    centre = [(a + b) / 2 for a, b in zip(lo, hi)]
    scale = 1.6 / max(b - a for a, b in zip(lo, hi))
    out = Path(__file__).with_name(f"{name}.obj")
    with out.open("w") as f:
        f.write(f"# {SOURCES[name]}\n")
        f.write(f"# {len(positions)} vertices, {len(cells)} triangles; made by convert_npm.py\n")
        for p in positions:
            f.write("v %.6f %.6f %.6f\n" % tuple((p[i] - centre[i]) * scale for i in range(3)))
        for c in cells:
            f.write("f %d %d %d\n" % tuple(i + 1 for i in c))
    print(f"wrote {out}: {len(positions)} vertices, {len(cells)} triangles")


if __name__ == "__main__":
    for name, path in zip(["teapot", "bunny"], sys.argv[1:3]):
        convert(name, path)
