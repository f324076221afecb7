#!/usr/bin/env python3
"""Path-traced reference of a translucent ball (or closed mesh) for the translucency accuracy example.

Mitsuba 3 (`pip install mitsuba`, version 3.9.1 used) renders a homogeneous scattering medium
inside a sphere whose boundary is index-matched (a `null` BSDF: no Fresnel reflection or
refraction, so the picture is the diffuse light that comes out of the medium alone), lit by
one directional light, seen by a perspective camera; volumetric path tracing with multiple
scattering to any depth (`volpathmis` by default, Russian roulette after 64 bounces).

Two things the first version got wrong, both measured against the light tracer
(tools/translucent_light_tracer.py) and a quadrature of single scattering:

- **The scene is rendered in millimetres**, not metres. Mitsuba offsets every ray it spawns
  by about 9e-5 × (1 + the largest coordinate); with a 1 cm ball in metres that is 0.09 mm,
  and the camera ray's first flight inside the medium starts that deep: in a medium whose
  mean free path is 0.45 mm (marble) the light scattered in that skin is lost (single
  scattering of a dense slab came out at exp(−σt·9e-5 m/μ_light): 0.76 at normal incidence,
  0.57 at 60°). In millimetres the offset is 1e-3 mm and single scattering agrees with the
  quadrature to 1 %.
- **`volpathmis`**, Mitsuba's spectral-MIS volumetric path tracer: `volpath` samples free
  flights in one colour channel and weights the others by the ratio of transmittances, whose
  variance is unbounded once one channel's extinction is twice another's (skin's blue
  against its red): its estimate is heavy-tailed and usually low. Its documentation points
  to `volpathmis` for media whose extinction varies with colour.

The example `translucent_accuracy` prints the exact command for its scene:The example `translucent_accuracy` prints the exact command for its scene:

    python3 tools/translucent_reference.py --sigma-a 0.032,0.17,0.48 \
        --sigma-s 0.74,0.88,1.01 --radius 0.01 --eye 0,0,0.04 --light=-1,-0.2,-0.3 \
        --size 96 --spp 1024 --out out/translucent_accuracy/reference.exr

Arguments in metres and per millimetre, as the example's scene; radiance per unit irradiance
of the light (irradiance 1 on a plane facing it), which does not depend on the unit of
length. Not needed by the crate or its tests.

`--point-light DISTANCE` (metres) puts a point light that far back along `--light` from the
origin instead of the directional light, of irradiance 1 across its rays at the origin (the
accuracy example's `--point-light`).

`--mesh FILE.obj` (metres, closed) renders that mesh's medium instead of the ball: the
accuracy example writes the very triangles its patches come from (`--shape bunny`);
index-matched under the directional light only. `--seed` picks the sampler's seed: two
renders of different seeds averaged make a reference, and half their difference is its noise.

`--eta 1.3` puts a smooth dielectric boundary round the medium instead (Mitsuba's
`dielectric`: Fresnel reflection and refraction both ways, total internal reflection). A
directional light cannot reach the camera through it by any path Mitsuba samples (a delta
light behind a delta interface), so a dielectric ball is lit by `--uniform`: a uniform
environment of radiance 1 (Bevy's ambient light) in place of the light. The environment's
mirror image in the ball's outer surface, `F(cos θ)` times 1 for a convex ball, and the
environment seen beside the ball are taken out of each pixel (averaged over 8×8 rays a
pixel), leaving the light that came through the medium.
"""

import argparse
import sys

from translucent_scene import add_scene_arguments, numbers, point_light_position


def plate_matrix(plate, scale):
    """The 4×4 matrix taking Mitsuba's rectangle onto the plate X,Y,Z,U,V (times `scale`)."""
    c, u, v = plate[0:3], plate[3:6], plate[6:9]
    n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    length = sum(x * x for x in n) ** 0.5
    n = [x / length for x in n]
    return [[scale * u[i], scale * v[i], n[i], scale * c[i]] for i in range(3)] + [[0.0, 0.0, 0.0, 1.0]]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_arguments(parser)
    parser.add_argument("--spp", type=int, default=1024, help="samples per pixel")
    parser.add_argument("--integrator", default="volpathmis", choices=["volpathmis", "volpath"],
                        help="volumetric path tracer (volpath only to reproduce old figures)")
    parser.add_argument("--eta", type=float, default=1.0,
                        help="index of refraction of the ball (1: index-matched, no boundary)")
    parser.add_argument("--uniform", action="store_true",
                        help="a uniform environment of radiance 1 instead of the light")
    parser.add_argument("--max-depth", type=int, default=-1,
                        help="longest path (2: single scattering alone; -1: unbounded)")
    parser.add_argument("--floor", type=numbers(5), default=None, metavar="X,Y,Z,HALF,ALBEDO",
                        help="a level square Lambertian floor centred at X,Y,Z (metres), HALF its "
                             "half-side, of grey ALBEDO, facing up (the accuracy example's --floor)")
    parser.add_argument("--occluder", type=numbers(9), default=None, metavar="X,Y,Z,UX,UY,UZ,VX,VY,VZ",
                        help="a black square plate centred at X,Y,Z (metres) with half-axes U and V "
                             "(the accuracy example's --occluder)")
    parser.add_argument("--seed", type=int, default=0,
                        help="the sampler's seed (two renders of different seeds give the noise)")
    args = parser.parse_args()
    if args.mesh is not None and (args.eta != 1.0 or args.uniform):
        parser.error("--mesh is index-matched under the directional light only (the environment's "
                     "reflection is taken out for the ball alone)")
    if not 1.0 <= args.eta <= 3.0:
        parser.error("--eta must lie in 1 – 3")
    if args.eta != 1.0 and not args.uniform:
        parser.error("a dielectric ball (--eta > 1) needs --uniform: a directional light "
                     "cannot reach the camera through a smooth boundary")
    if (args.radius is not None and args.radius <= 0) or args.size <= 0 or args.spp <= 0:
        parser.error("--radius, --size and --spp must be positive")
    if args.point_light is not None and (not args.point_light > 0 or args.uniform):
        parser.error("--point-light takes a positive distance, and not with --uniform")

    floor, occluder = args.floor, args.occluder
    if floor is not None:
        if not floor[3] > 0 or not 0 <= floor[4] <= 1:
            parser.error("--floor takes X,Y,Z,HALF,ALBEDO: a positive half-side and an albedo in 0 - 1")
        if args.uniform:
            parser.error("--floor takes the directional or point light, not --uniform")

    import mitsuba as mi

    # The scalar variant: drjit's LLVM back end needs a newer libLLVM than Debian 12 ships.
    mi.set_variant("scalar_rgb")
    # In millimetres: Mitsuba's ray offsets are relative to the coordinates' size (above).
    mm = 1000.0
    per_mm = [a + s for a, s in zip(args.sigma_a, args.sigma_s)]
    albedo = [s / (a + s) for a, s in zip(args.sigma_a, args.sigma_s)]
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": args.integrator, "max_depth": args.max_depth, "rr_depth": 64},
        "sensor": {
            "type": "perspective",
            "fov": args.fov,
            "fov_axis": "y",
            "near_clip": 0.5,
            "to_world": mi.ScalarTransform4f().look_at(origin=[mm * v for v in args.eye], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": args.size, "height": args.size,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": args.spp, "seed": args.seed},
        },
        "ball": {
            **({"type": "sphere", "radius": mm * args.radius} if args.mesh is None else
               {"type": "obj", "filename": args.mesh, "face_normals": True,
                "to_world": mi.ScalarTransform4f().scale(mm)}),
            "bsdf": {"type": "null"} if args.eta == 1.0
            else {"type": "dielectric", "int_ior": args.eta, "ext_ior": 1.0},
            "interior": {
                "type": "homogeneous",
                "albedo": {"type": "rgb", "value": albedo},
                # RGB values must lie in [0, 1]: the largest channel goes into the scale.
                "sigma_t": {"type": "rgb", "value": [v / max(per_mm) for v in per_mm]},
                "scale": max(per_mm),
                "phase": {"type": "isotropic"},
            },
        },
        **({"floor": {
            "type": "rectangle",
            # Mitsuba's rectangle spans [-1, 1]² in z = 0 facing +z: turned to face +y.
            "to_world": mi.ScalarTransform4f().translate([mm * v for v in floor[:3]])
            @ mi.ScalarTransform4f().rotate([1, 0, 0], -90)
            @ mi.ScalarTransform4f().scale([mm * floor[3]] * 3),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [floor[4]] * 3}},
        }} if floor is not None else {}),
        **({"occluder": {
            "type": "rectangle",
            # The rectangle's [-1, 1]² in z = 0 onto the plate: x along U, y along V.
            "to_world": mi.ScalarTransform4f(plate_matrix(occluder, mm)),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}},
        }} if occluder is not None else {}),
        **({"environment": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}
           if args.uniform else
           {"sun": {"type": "directional", "direction": args.light,
                    "irradiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}
           if args.point_light is None else
           {"lamp": {"type": "point", "position": point_light_position(args, mm),
                     # Irradiance 1 across its rays at the origin, in millimetres.
                     "intensity": {"type": "rgb", "value": [(mm * args.point_light) ** 2] * 3}}}),
    })
    image = mi.render(scene)
    if args.uniform:
        import numpy as np
        image = np.array(image, dtype=np.float64)
        image -= environment_seen(args)[:, :, None]
        image = mi.Bitmap(image.astype(np.float32))
    mi.Bitmap(image).write(args.out)
    print(f"wrote {args.out}")




def fresnel(cos_i, eta):
    """Unpolarised Fresnel reflectance from outside onto index `eta` (numpy arrays)."""
    import numpy as np
    cos_t = np.sqrt(np.maximum(1.0 - (1.0 - cos_i * cos_i) / (eta * eta), 0.0))
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp)


def camera_rays_into_ball(n, fov, eye, radius):
    """The camera's n × n unit ray directions (at `eye`, looking at the origin, y up,
    vertical field of view `fov` degrees, pixel centres, rows from the top) and where each
    meets the ball of `radius` about the origin: (directions, hit, near, far), the distances
    along each ray where it enters and leaves (numpy arrays; meaningless where not hit)."""
    import numpy as np
    tan = np.tan(np.radians(fov) / 2.0)
    u = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    sx, sy = np.meshgrid(u * tan, -u * tan)
    forward = -eye / np.linalg.norm(eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = forward + sx[..., None] * right + sy[..., None] * up
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    b = d @ eye
    disc = b * b - (eye @ eye - radius ** 2)
    hit = disc > 0.0
    root = np.sqrt(np.where(hit, disc, 0.0))
    return d, hit, -b - root, -b + root


def environment_seen(args):
    """Per pixel, how much of the uniform environment the camera sees other than through the
    medium: directly beside the ball (1), and mirrored in its outer surface (Fresnel's
    reflectance; 0 when index-matched), averaged over 8×8 rays a pixel (the camera looks at
    the ball's centre, so the picture is symmetric and its axes' orientation does not
    matter)."""
    import numpy as np
    sub = 8
    eye = np.array(args.eye, dtype=np.float64)
    d, hit, t, _ = camera_rays_into_ball(args.size * sub, args.fov, eye, args.radius)
    normal = (eye + t[..., None] * d) / args.radius
    cos_i = np.clip(-(d * normal).sum(-1), 0.0, 1.0)
    reflected = np.where(hit, fresnel(cos_i, args.eta), 1.0)
    return reflected.reshape(args.size, sub, args.size, sub).mean(axis=(1, 3))


if __name__ == "__main__":
    sys.exit(main())
