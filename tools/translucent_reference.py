#!/usr/bin/env python3
"""Path-traced reference of a translucent ball for the translucency accuracy example.

Mitsuba 3 (`pip install mitsuba`, version 3.9.1 used) renders a homogeneous scattering medium
inside a sphere whose boundary is index-matched (a `null` BSDF: no Fresnel reflection or
refraction, so the picture is the diffuse light that comes out of the medium alone), lit by
one directional light, seen by a perspective camera; volumetric path tracing with multiple
scattering to any depth (`volpath`, Russian roulette after 64 bounces). Scene in metres; the
medium's coefficients are given per millimetre and scaled by 1000.

The example `translucent_accuracy` prints the exact command for its scene:

    python3 tools/translucent_reference.py --sigma-a 0.032,0.17,0.48 \
        --sigma-s 0.74,0.88,1.01 --radius 0.01 --eye 0,0,0.04 --light=-1,-0.2,-0.3 \
        --size 96 --spp 1024 --out out/translucent_accuracy/reference.exr

Radiance per unit irradiance of the light (irradiance 1 on a plane facing it). Not needed by
the crate or its tests.
"""

import argparse
import sys


def triple(text):
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not three comma-separated numbers")
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"{text!r} is not three comma-separated numbers")
    return values


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sigma-a", type=triple, required=True, help="absorption per mm, r,g,b")
    parser.add_argument("--sigma-s", type=triple, required=True, help="scattering per mm (g = 0), r,g,b")
    parser.add_argument("--radius", type=float, required=True, help="ball radius, metres")
    parser.add_argument("--eye", type=triple, required=True, help="camera position (looks at the origin, +Y up)")
    parser.add_argument("--light", type=triple, required=True, help="direction the light travels")
    parser.add_argument("--fov", type=float, default=45.0, help="vertical field of view, degrees")
    parser.add_argument("--size", type=int, default=96, help="image width = height, pixels")
    parser.add_argument("--spp", type=int, default=1024, help="samples per pixel")
    parser.add_argument("--out", required=True, help="EXR to write")
    args = parser.parse_args()
    if args.radius <= 0 or args.size <= 0 or args.spp <= 0:
        parser.error("--radius, --size and --spp must be positive")

    import mitsuba as mi

    # The scalar variant: drjit's LLVM back end needs a newer libLLVM than Debian 12 ships.
    mi.set_variant("scalar_rgb")
    per_m = [1000.0 * (a + s) for a, s in zip(args.sigma_a, args.sigma_s)]
    albedo = [s / (a + s) for a, s in zip(args.sigma_a, args.sigma_s)]
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": 64},
        "sensor": {
            "type": "perspective",
            "fov": args.fov,
            "fov_axis": "y",
            "near_clip": 0.0005,
            "to_world": mi.ScalarTransform4f().look_at(origin=args.eye, target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": args.size, "height": args.size,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": args.spp},
        },
        "ball": {
            "type": "sphere",
            "radius": args.radius,
            "bsdf": {"type": "null"},
            "interior": {
                "type": "homogeneous",
                "albedo": {"type": "rgb", "value": albedo},
                # RGB values must lie in [0, 1]: the largest channel goes into the scale.
                "sigma_t": {"type": "rgb", "value": [v / max(per_m) for v in per_m]},
                "scale": max(per_m),
                "phase": {"type": "isotropic"},
            },
        },
        "sun": {"type": "directional", "direction": args.light, "irradiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}},
    })
    image = mi.render(scene)
    mi.Bitmap(image).write(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    sys.exit(main())
