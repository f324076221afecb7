#!/usr/bin/env python3
"""The single scattering of a directional light's beam inside an index-matched ball, per pixel
of `translucent_accuracy`'s camera, as a share of a reference picture: how much of what a
path tracer sees would a per-pixel single-scattering march (a light-view depth map, as
translucent shadow maps do) add, where the plugin's patches give none of it (docs/translucent.md,
"Which stage carries the error").

Each pixel's ray enters the ball (radius 1 cm, seen from 4 cm, field of view 45°) and is
marched through it in 400 steps; at each, the beam arrives attenuated by the medium between
the step and the surface towards the light, scatters isotropically (σs′/4π) and leaves
attenuated along the ray: L = ∫ σs′/(4π) e^(−σt (t_light + s)) ds, for an irradiance of 1
across the beam. Pixels facing the camera at a cosine of 0.3 or more are summed, as the
example scores them.

    python3 tools/translucent_ball_single_scattering.py --sigma-a 0.032,0.17,0.48 \\
        --sigma-s 0.74,0.88,1.01 --light=0.4,-0.2,1 \\
        --reference tests/data/translucent/skin1_back_lighttraced.exr

Needs `mitsuba` (to read the EXR) and `numpy` (PyPI); not needed by the crate.
"""

import argparse
import sys

# The accuracy scene's camera, as the reference renders it.
from translucent_reference import camera_rays_into_ball


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    three = lambda text: [float(v) for v in text.split(",")]
    parser.add_argument("--sigma-a", type=three, required=True, help="absorption per mm, r,g,b")
    parser.add_argument("--sigma-s", type=three, required=True, help="reduced scattering per mm, r,g,b")
    parser.add_argument("--light", type=three, required=True, help="the way the light travels, x,y,z")
    parser.add_argument("--reference", required=True, help="the reference EXR (96 x 96)")
    args = parser.parse_args()
    if len(args.sigma_a) != 3 or len(args.sigma_s) != 3 or len(args.light) != 3:
        parser.error("--sigma-a, --sigma-s and --light take three numbers each")

    import numpy as np
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    reference = np.array(mi.Bitmap(args.reference))[:, :, :3].astype(np.float64)
    size = reference.shape[0]
    scattering = np.array(args.sigma_s) * 1000.0  # per metre
    extinction = scattering + np.array(args.sigma_a) * 1000.0
    light = np.array(args.light, dtype=np.float64)
    light /= np.linalg.norm(light)
    radius, eye = 0.01, np.array([0.0, 0.0, 0.04])
    d, hit, near, far = camera_rays_into_ball(size, 45.0, eye, radius)
    entry = eye + near[..., None] * d
    facing = -(d * entry / radius).sum(-1)
    steps = 400
    single = np.zeros((size, size, 3))
    for k in range(steps):
        s = (far - near) * (k + 0.5) / steps
        p = entry + d * s[..., None]
        # Distance from p to the surface towards the light.
        pb = -(p * light).sum(-1)
        to_light = -pb + np.sqrt(np.maximum(pb * pb - ((p * p).sum(-1) - radius * radius), 0.0))
        step = (far - near) / steps
        single += (scattering / (4.0 * np.pi)) * np.exp(-extinction * (to_light + s)[..., None]) * step[..., None]
    scored = hit & (facing >= 0.3)
    share = single[scored].sum(0) / reference[scored].sum(0)
    print("single scattering over the reference, r g b: " + " ".join(f"{v:.3f}" for v in share))


if __name__ == "__main__":
    sys.exit(main())
