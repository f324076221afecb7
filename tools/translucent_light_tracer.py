#!/usr/bin/env python3
"""Light-traced reference of a translucent ball, for scenes a camera path tracer cannot converge.

Lit from behind, almost none of the light that reaches the camera's side of the ball gets
there in a straight line: Mitsuba's `volpath` (tools/translucent_reference.py) has to find
the light by walks started at the camera, and its next-event rays to a directional light
cross the whole ball, so its picture is mostly fireflies (two renders at 1024 and 4096 spp
differ by 0.5–1.3 in relative L1). Mitsuba's particle tracer (`ptracer`) does not trace
media (it renders the ball black). This tool runs the walks the other way, from the light:

- photons enter the ball uniformly over its disc seen from the light (irradiance 1 on a plane
  facing the light), index-matched boundary (no Fresnel, no refraction), as in
  translucent_reference.py;
- free flights in the homogeneous medium (σt = σa + σs, g = 0), the weight times the albedo
  σs/σt at each collision (Russian roulette below 1/20 of the start);
- at every collision the photon's in-scattered light is sent to the pinhole camera (next-event
  estimation toward the eye: the isotropic phase 1/4π, the medium's transmittance to the
  boundary on the way to the eye, 1/r², and the pinhole's importance 1/(a cos³θ) for a pixel
  of area a on the image plane at distance 1), into the pixel the eye sees it through.

The estimator is the adjoint of `volpath`'s: same scene, same units (radiance per unit
irradiance), so front-lit pictures of the two agree to the path tracer's noise (checked:
run both, compare). Every contribution is bounded (T ≤ 1, r ≥ the eye's distance to the
ball), so there are no fireflies, lit from any side. Each channel is walked on its own.

    python3 tools/translucent_light_tracer.py --sigma-a 0.032,0.17,0.48 \
        --sigma-s 0.74,0.88,1.01 --radius 0.01 --eye 0,0,0.04 --light=0.4,-0.2,1 \
        --size 96 --photons 4000000 --out out/translucent_accuracy/light_traced.exr

Prints its own noise: the relative L1 between the pictures of the two halves of the photons,
halved (the full picture's expected distance from the converged one). Needs numpy, and
mitsuba for writing the EXR. Not needed by the crate or its tests.
"""

import argparse
import math
import sys
import time

import numpy as np

from translucent_scene import add_scene_arguments


def normalize(v):
    return v / np.linalg.norm(v)


def exit_distance(x, w, radius):
    """Distance from x (inside the ball) along unit w to the sphere."""
    b = np.einsum("ij,ij->i", x, w)
    c = np.einsum("ij,ij->i", x, x) - radius * radius
    return -b + np.sqrt(np.maximum(b * b - c, 0.0))


def trace_channel(sigma_t, albedo, args, camera, rng, batch):
    """One channel's picture from `batch` photons (the caller splits the total)."""
    eye, forward, right, up, tan_half = camera
    size, radius = args.size, args.radius
    light = normalize(np.array(args.light))
    helper = np.array([0.0, 1.0, 0.0]) if abs(light[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    lu = normalize(np.cross(light, helper))
    lv = np.cross(light, lu)
    image = np.zeros(size * size)
    # Irradiance 1 over the ball's disc πR², shared by the photons.
    power = math.pi * radius * radius / batch
    pixel_area = (2.0 * tan_half / size) ** 2

    r = radius * np.sqrt(rng.random(batch))
    phi = 2.0 * math.pi * rng.random(batch)
    origin = (r * np.cos(phi))[:, None] * lu + (r * np.sin(phi))[:, None] * lv - 2.0 * radius * light
    b = origin @ light
    c = np.einsum("ij,ij->i", origin, origin) - radius * radius
    x = origin + (-b - np.sqrt(np.maximum(b * b - c, 0.0)))[:, None] * light
    w = np.tile(light, (batch, 1))
    weight = np.full(batch, power)
    while len(x):
        flight = -np.log(1.0 - rng.random(len(x))) / sigma_t
        inside = flight < exit_distance(x, w, radius)
        x, w, weight, flight = x[inside], w[inside], weight[inside], flight[inside]
        if not len(x):
            break
        x = x + flight[:, None] * w
        weight = weight * albedo
        # Next-event estimation toward the eye.
        to_eye = eye - x
        r2 = np.einsum("ij,ij->i", to_eye, to_eye)
        w_eye = to_eye / np.sqrt(r2)[:, None]
        transmittance = np.exp(-sigma_t * exit_distance(x, w_eye, radius))
        d = -w_eye
        cos_theta = d @ forward
        sx = (d @ right) / cos_theta / tan_half
        sy = (d @ up) / cos_theta / tan_half
        px = np.floor((sx + 1.0) * 0.5 * size).astype(np.int64)
        py = np.floor((1.0 - sy) * 0.5 * size).astype(np.int64)
        seen = (px >= 0) & (px < size) & (py >= 0) & (py < size) & (cos_theta > 0)
        contribution = weight * transmittance / (4.0 * math.pi * r2 * pixel_area * cos_theta**3)
        image += np.bincount((py * size + px)[seen], weights=contribution[seen], minlength=size * size)
        # Isotropic scattering.
        cz = 2.0 * rng.random(len(x)) - 1.0
        sz = np.sqrt(np.maximum(0.0, 1.0 - cz * cz))
        a = 2.0 * math.pi * rng.random(len(x))
        w = np.stack([sz * np.cos(a), sz * np.sin(a), cz], axis=1)
        # Russian roulette once a photon keeps less than 1/20 of its start.
        low = weight < power / 20.0
        survive = ~low | (rng.random(len(x)) < 0.5)
        weight = np.where(low, weight * 2.0, weight)
        x, w, weight = x[survive], w[survive], weight[survive]
    return image.reshape(size, size)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_arguments(parser)
    parser.add_argument("--photons", type=int, default=2_000_000, help="photons per channel")
    parser.add_argument("--batch", type=int, default=250_000, help="photons walked at once")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    if args.radius <= 0 or args.size <= 0 or args.photons < 2 or args.batch <= 0:
        parser.error("--radius, --size and --batch must be positive, --photons at least 2")
    if not all(a >= 0 and s > 0 for a, s in zip(args.sigma_a, args.sigma_s)):
        parser.error("--sigma-a must be ≥ 0 and --sigma-s > 0 in every channel")
    if np.linalg.norm(args.light) == 0 or np.linalg.norm(args.eye) <= args.radius:
        parser.error("--light must be a direction and --eye outside the ball")
    if np.linalg.norm(np.cross(args.eye, [0.0, 1.0, 0.0])) < 1e-9 * np.linalg.norm(args.eye):
        parser.error("--eye must not be straight above or below the ball (+Y is up)")

    eye = np.array(args.eye)
    forward = normalize(-eye)
    right = normalize(np.cross(forward, [0.0, 1.0, 0.0]))
    up = np.cross(right, forward)
    camera = (eye, forward, right, up, math.tan(math.radians(args.fov) / 2.0))
    rng = np.random.default_rng(args.seed)
    batches = 2 * max(1, math.ceil(args.photons / (2 * args.batch)))
    batch = args.photons // batches
    halves = np.zeros((2, args.size, args.size, 3))
    start = time.time()
    for ch in range(3):
        # Per metre: the coefficients are per millimetre.
        sigma_t = 1000.0 * (args.sigma_a[ch] + args.sigma_s[ch])
        albedo = args.sigma_s[ch] / (args.sigma_a[ch] + args.sigma_s[ch])
        for k in range(batches):
            halves[k % 2, :, :, ch] += trace_channel(sigma_t, albedo, args, camera, rng, batch)
        print(f"channel {ch}: {time.time() - start:.0f} s", file=sys.stderr)
    halves /= batches // 2
    image = halves.mean(axis=0)
    ball = image.sum(axis=2) > 0
    noise = np.abs(halves[0] - halves[1])[ball].sum() / max(2.0 * image[ball].sum(), 1e-30)
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    mi.Bitmap(image.astype(np.float32)).write(args.out)
    print(f"wrote {args.out}: {batches * batch} photons a channel in {time.time() - start:.0f} s, "
          f"noise (relative L1 of the halves' difference / 2) {noise:.4f}")


if __name__ == "__main__":
    sys.exit(main())
