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

`--eta 1.3` puts a smooth dielectric boundary round the medium (as Mitsuba's `dielectric`):
- photons enter by Fresnel's transmittance at their incidence and refract;
- at the boundary from inside they reflect back in with Fresnel's probability (always past
  the critical angle), else leave;
- the connection to the eye leaves by refraction: the exit point by Fermat's principle (the
  least optical length `η|s − x| + |eye − s|` over the cap the eye sees, a golden-section
  search in the plane of the centre, the point and the eye; Snell's law checked to 1e-4),
  Fresnel's transmittance out, and in place of 1/r² the solid angle per area at the eye
  `dω_x/dA_eye = dΩ_eye/(η² dA_x)` (étendue), `dA_x` from two neighbouring rays traced in
  from the eye. With η = 1 this connection equals the straight one to 1e-5 (checked).
`--part single|grazing-entry` renders one part of the picture: single scattering alone (each
photon's first collision; index-matched only — behind a dielectric the photons reflected at
the boundary before their first collision are left out), or the light of the photons that
entered at a grazing angle (incidence cosine below 0.3). `--part lambertian-exit`
(index-matched only) renders what any method that gives light out by Lambert's law would
show with the exact transport: each photon's exit is counted as flux on the surface point it
leaves by, seen through its pixel, and the pixel's radiance is that exitance over π (flux ×
the exit's view cosine / (π · the pixel's solid angle · r²)); the unscattered beam is not
counted. `--part lobe-exit` gives the same exits out by a lobe instead: per pixel, the von
Mises–Fisher lobe `exp(k ω·u)` on the outward hemisphere whose flux-weighted mean exit
direction is the exits' own (fitted on a grid of k and u's angle to the normal), scaled to
their exitance — what a method that carried each patch's mean exit direction could give. `--point-light DISTANCE` lights it by a point light that far back along `--light` instead, of
irradiance 1 across its rays at the centre (photons uniform in solid angle over the cone the
ball subtends). `--uniform` lights the ball by a uniform environment of radiance 1 instead (photons start
uniformly over the sphere, cosine-distributed inward): against Mitsuba's reference of the
same scene it checks the dielectric machinery end to end.

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

from translucent_scene import add_scene_arguments, point_light_position


def normalize(v):
    return v / np.linalg.norm(v)


def dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def fresnel(cos_i, eta):
    """Unpolarised Fresnel reflectance for light meeting a boundary at incidence cosine
    `cos_i` from a side of index 1 onto index `eta` (eta < 1: from inside; 1 past the critical
    angle)."""
    sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta)
    cos_t = np.sqrt(np.maximum(1.0 - sin_t2, 0.0))
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return np.where(sin_t2 >= 1.0, 1.0, 0.5 * (rs * rs + rp * rp))


def refract(w, n, eta):
    """`w` (unit, against the unit normal `n`: w·n < 0) into a medium `eta` times denser."""
    cos_i = -dot(w, n)
    sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta)
    cos_t = np.sqrt(np.maximum(1.0 - sin_t2, 0.0))
    return w / eta + ((cos_i / eta) - cos_t)[:, None] * n


def refracted_connection(x, eye, radius, eta, sigma_t):
    """For points `x` inside a ball of index `eta`, the path to the eye through the boundary
    by Fermat's principle (the least optical length over the cap the eye sees, golden-section
    search in the plane of the centre, the point and the eye): where it leaves, the
    medium's transmittance to there times Fresnel's transmittance out, and the solid angle
    per area at the eye `dω_x/dA_eye = dΩ_eye/(η² dA_x)` (étendue), `dA_x` from two
    neighbouring rays traced from the eye. Returns (exit points, factor, valid)."""
    e = np.linalg.norm(eye)
    axis = eye / e
    along = x @ axis
    across = x - along[:, None] * axis
    a_len = np.linalg.norm(across, axis=1)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    fallback = np.cross(axis, helper)
    fallback /= np.linalg.norm(fallback)
    side = np.where(a_len[:, None] > 1e-12 * radius, across / np.maximum(a_len, 1e-300)[:, None], fallback)
    limit = math.acos(radius / e)

    def optical(phi):
        s = radius * (np.cos(phi)[:, None] * axis + np.sin(phi)[:, None] * side)
        return eta * np.linalg.norm(s - x, axis=1) + np.linalg.norm(eye - s, axis=1)

    lo = np.full(len(x), -limit)
    hi = np.full(len(x), limit)
    # Golden-section search, one new evaluation a step (the other interior point is kept):
    # 36 steps leave 1.6 × 0.618³⁶ ≈ 5e-8 rad, Snell's residual far below the check's 1e-4.
    golden = (math.sqrt(5.0) - 1.0) / 2.0
    c = hi - golden * (hi - lo)
    d = lo + golden * (hi - lo)
    fc, fd = optical(c), optical(d)
    for _ in range(36):
        left = fc < fd
        hi = np.where(left, d, hi)
        lo = np.where(left, lo, c)
        # Left: the new d is the old c; right: the new c is the old d.
        new = np.where(left, hi - golden * (hi - lo), lo + golden * (hi - lo))
        f_new = optical(new)
        c, d = np.where(left, new, d), np.where(left, c, new)
        fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
    phi = 0.5 * (lo + hi)
    s = radius * (np.cos(phi)[:, None] * axis + np.sin(phi)[:, None] * side)
    n = s / radius
    inside = s - x
    inside_len = np.linalg.norm(inside, axis=1)
    w_in = inside / inside_len[:, None]
    out = eye - s
    w_out = out / np.linalg.norm(out, axis=1)[:, None]
    cos_in, cos_out = dot(w_in, n), dot(w_out, n)
    # Snell holds at a stationary point: tangential components η w_in = w_out.
    tangent_in = w_in - cos_in[:, None] * n
    tangent_out = w_out - cos_out[:, None] * n
    snell = np.linalg.norm(eta * tangent_in - tangent_out, axis=1)
    valid = (snell < 1e-4) & (cos_in > 0) & (cos_out > 0) & (phi > -limit + 1e-9) & (phi < limit - 1e-9)
    transmitted = 1.0 - fresnel(cos_out, eta)
    # dA_x: the cross-section at x of the tube of rays the eye sends through a small solid
    # angle about -w_out (refracted in at the ball), perpendicular to w_in.
    delta = 1e-4
    u = np.cross(w_out, np.array([0.0, 1.0, 0.0]))
    u = np.where(np.linalg.norm(u, axis=1)[:, None] > 1e-6, u, np.cross(w_out, np.array([1.0, 0.0, 0.0])))
    u /= np.linalg.norm(u, axis=1)[:, None]
    v = np.cross(w_out, u)
    offsets = []
    for du, dv in ((delta, 0.0), (0.0, delta)):
        ray = -w_out + du * u + dv * v
        ray /= np.linalg.norm(ray, axis=1)[:, None]
        b = ray @ eye
        cc = eye @ eye - radius * radius
        t = -b - np.sqrt(np.maximum(b * b - cc, 0.0))
        hit = eye + t[:, None] * ray
        refracted = refract(ray, hit / radius, eta)
        # Where it crosses the plane through x perpendicular to the central ray inside.
        along = dot(refracted, w_in)
        k = dot(x - hit, w_in) / np.where(np.abs(along) > 1e-12, along, -1e-12)
        offsets.append(hit + k[:, None] * refracted - x)
    area = np.linalg.norm(np.cross(offsets[0], offsets[1]), axis=1)
    solid_angle = delta * delta
    per_area = solid_angle / np.maximum(area, 1e-300) / (eta * eta)
    factor = np.exp(-sigma_t * inside_len) * transmitted * per_area
    return s, factor, valid & (area > 0)


def exit_distance(x, w, radius):
    """Distance from x (inside the ball) along unit w to the sphere."""
    b = np.einsum("ij,ij->i", x, w)
    c = np.einsum("ij,ij->i", x, x) - radius * radius
    return -b + np.sqrt(np.maximum(b * b - c, 0.0))


def scatter_and_roulette(x, weight, power, rng):
    """Isotropic scattering at every collision, and Russian roulette once a photon keeps
    less than 1/20 of its start. Returns the survivors' (x, w, weight)."""
    cz = 2.0 * rng.random(len(x)) - 1.0
    sz = np.sqrt(np.maximum(0.0, 1.0 - cz * cz))
    a = 2.0 * math.pi * rng.random(len(x))
    w = np.stack([sz * np.cos(a), sz * np.sin(a), cz], axis=1)
    low = weight < power / 20.0
    survive = ~low | (rng.random(len(x)) < 0.5)
    weight = np.where(low, weight * 2.0, weight)
    return x[survive], w[survive], weight[survive]


def trace_channel(sigma_t, albedo, args, camera, rng, batch):
    """One channel's picture from `batch` photons (the caller splits the total)."""
    eye, forward, right, up, tan_half = camera
    size, radius, eta = args.size, args.radius, args.eta
    light = normalize(np.array(args.light))
    helper = np.array([0.0, 1.0, 0.0]) if abs(light[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    lu = normalize(np.cross(light, helper))
    lv = np.cross(light, lu)
    image = np.zeros(size * size)
    # The exits' flux-weighted directions (--part lobe-exit).
    moments = np.zeros((size * size, 3))
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
    if args.point_light is not None:
        # A point light `--point-light` back along the light, of intensity d² (irradiance 1
        # across its rays at the centre): photons uniform in solid angle over the cone the
        # ball subtends from it, each carrying d² Ω / batch, entering where they first meet
        # the ball.
        d = args.point_light
        lamp = np.array(point_light_position(args))
        cos_max = math.sqrt(max(0.0, 1.0 - (radius / d) ** 2))
        power = d * d * 2.0 * math.pi * (1.0 - cos_max) / batch
        ct = 1.0 - rng.random(batch) * (1.0 - cos_max)
        st = np.sqrt(np.maximum(0.0, 1.0 - ct * ct))
        phi = 2.0 * math.pi * rng.random(batch)
        w = ct[:, None] * light + (st * np.cos(phi))[:, None] * lu + (st * np.sin(phi))[:, None] * lv
        b = w @ lamp
        c = lamp @ lamp - radius * radius
        x = lamp + (-b - np.sqrt(np.maximum(b * b - c, 0.0)))[:, None] * w
    if args.uniform:
        # A uniform environment of radiance 1: irradiance π on every point of the ball,
        # 4π²R² in all; photons start uniformly over the sphere, cosine-distributed inward.
        power = 4.0 * math.pi**2 * radius * radius / batch
        cz = 2.0 * rng.random(batch) - 1.0
        a = 2.0 * math.pi * rng.random(batch)
        sz = np.sqrt(np.maximum(0.0, 1.0 - cz * cz))
        n = np.stack([sz * np.cos(a), sz * np.sin(a), cz], axis=1)
        x = radius * n
        h = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
        t1 = np.cross(n, h)
        t1 /= np.linalg.norm(t1, axis=1)[:, None]
        t2 = np.cross(n, t1)
        r = np.sqrt(rng.random(batch))
        a = 2.0 * math.pi * rng.random(batch)
        w = ((r * np.cos(a))[:, None] * t1 + (r * np.sin(a))[:, None] * t2
             - np.sqrt(np.maximum(0.0, 1.0 - r * r))[:, None] * n)
    weight = np.full(batch, power)
    if args.part == "grazing-entry":
        # Only the photons that enter at a grazing angle (incidence cosine below 0.3).
        weight = weight * (-dot(w, x / radius) < 0.3)
    if eta != 1.0:
        # In through the boundary: Fresnel's share reflected away, the rest refracted.
        n = x / radius
        weight = weight * (1.0 - fresnel(-dot(w, n), eta))
        w = refract(w, n, eta)
        x = x - 1e-9 * radius * n
    collisions = 0
    while len(x):
        if args.part == "single" and collisions == 1:
            break
        flight = -np.log(1.0 - rng.random(len(x))) / sigma_t
        to_boundary = exit_distance(x, w, radius)
        inside = flight < to_boundary
        if eta != 1.0:
            # At the boundary from inside: Fresnel reflection back in (total past the
            # critical angle), else out.
            at = x[~inside] + to_boundary[~inside][:, None] * w[~inside]
            n = at / radius
            cos_i = dot(w[~inside], n)
            back = rng.random(len(at)) < fresnel(cos_i, 1.0 / eta)
            bounced_x = at[back] - 1e-9 * radius * n[back]
            bounced_w = w[~inside][back] - 2.0 * cos_i[back][:, None] * n[back]
            bounced_weight = weight[~inside][back]
        if args.part in ("lambertian-exit", "lobe-exit") and collisions > 0:
            # Exits after a scattering or more (the unscattered beam goes on along the light,
            # and no patch method gives it out) on the side the eye sees: radiance =
            # exitance / π, exitance = flux over the pixel's footprint (its solid angle
            # a cos³θ at r, over the exit's view cosine).
            s = x[~inside] + to_boundary[~inside][:, None] * w[~inside]
            to_eye = eye - s
            r2 = np.einsum("ij,ij->i", to_eye, to_eye)
            view_cos = dot(to_eye, s / radius) / np.sqrt(r2)
            d = -to_eye / np.sqrt(r2)[:, None]
            cos_theta = d @ forward
            sx = (d @ right) / cos_theta / tan_half
            sy = (d @ up) / cos_theta / tan_half
            px = np.floor((sx + 1.0) * 0.5 * size).astype(np.int64)
            py = np.floor((1.0 - sy) * 0.5 * size).astype(np.int64)
            seen = (px >= 0) & (px < size) & (py >= 0) & (py < size) & (cos_theta > 0) & (view_cos > 0)
            flux = weight[~inside] * view_cos / (math.pi * pixel_area * cos_theta**3 * r2)
            image += np.bincount((py * size + px)[seen], weights=flux[seen], minlength=size * size)
            for k in range(3):
                moments[:, k] += np.bincount((py * size + px)[seen],
                                             weights=(flux * w[~inside][:, k])[seen],
                                             minlength=size * size)
        x, w, weight, flight = x[inside], w[inside], weight[inside], flight[inside]
        if not len(x):
            if eta != 1.0 and len(bounced_x):
                x, w, weight = bounced_x, bounced_w, bounced_weight
                continue
            break
        x = x + flight[:, None] * w
        weight = weight * albedo
        collisions += 1
        if args.part in ("lambertian-exit", "lobe-exit"):
            x, w, weight = scatter_and_roulette(x, weight, power, rng)
            continue
        # Next-event estimation toward the eye: at every collision, or (--connect-fraction f)
        # at a random share of them, weighted by its inverse (unbiased; the refracted
        # connection's search is most of the cost behind a dielectric): f in the half of the
        # ball away from the eye, rising to 1 at the point nearest it, where the light that
        # reaches the camera is.
        if args.connect_fraction >= 1.0:
            xc, wc = x, weight
        else:
            towards = np.clip(x @ (eye / np.linalg.norm(eye)) / radius, 0.0, 1.0)
            chance = args.connect_fraction + (1.0 - args.connect_fraction) * towards
            pick = rng.random(len(x)) < chance
            xc, wc = x[pick], weight[pick] / chance[pick]
        if eta == 1.0:
            to_eye = eye - xc
            r2 = np.einsum("ij,ij->i", to_eye, to_eye)
            w_eye = to_eye / np.sqrt(r2)[:, None]
            transmittance = np.exp(-sigma_t * exit_distance(xc, w_eye, radius)) / r2
            connected = np.ones(len(xc), dtype=bool)
        else:
            s, transmittance, connected = refracted_connection(xc, eye, radius, eta, sigma_t)
            w_eye = (eye - s) / np.linalg.norm(eye - s, axis=1)[:, None]
        d = -w_eye
        cos_theta = d @ forward
        sx = (d @ right) / cos_theta / tan_half
        sy = (d @ up) / cos_theta / tan_half
        px = np.floor((sx + 1.0) * 0.5 * size).astype(np.int64)
        py = np.floor((1.0 - sy) * 0.5 * size).astype(np.int64)
        seen = (px >= 0) & (px < size) & (py >= 0) & (py < size) & (cos_theta > 0) & connected
        contribution = wc * transmittance / (4.0 * math.pi * pixel_area * cos_theta**3)
        image += np.bincount((py * size + px)[seen], weights=contribution[seen], minlength=size * size)
        x, w, weight = scatter_and_roulette(x, weight, power, rng)
        if eta != 1.0 and len(bounced_x):
            x = np.concatenate([x, bounced_x])
            w = np.concatenate([w, bounced_w])
            weight = np.concatenate([weight, bounced_weight])
    return image.reshape(size, size), moments.reshape(size, size, 3)


def lobe_exit_radiance(exitance, moments, camera, radius):
    """Per pixel, the radiance toward the eye of a von Mises–Fisher lobe `A exp(k ω·u)` on
    the outward hemisphere of the point the pixel's centre sees, with the exits' exitance
    (`exitance`, over π) and flux-weighted mean exit direction (`moments / exitance`): k and
    u's angle to the normal from the nearest point of a grid of lobes' mean directions."""
    eye, forward, right, up, tan_half = camera
    size = exitance.shape[0]
    # Hemisphere quadrature about +z, uniform in the cosine and the azimuth.
    cos_q, az_q = np.meshgrid((np.arange(48) + 0.5) / 48, (np.arange(96) + 0.5) / 96 * 2 * math.pi)
    cos_q, az_q = cos_q.ravel(), az_q.ravel()
    sin_q = np.sqrt(1.0 - cos_q**2)
    omega = np.stack([sin_q * np.cos(az_q), sin_q * np.sin(az_q), cos_q], axis=1)
    grid = []
    for k in np.concatenate([[0.0], np.geomspace(0.05, 60.0, 80)]):
        for angle in np.linspace(0.0, math.pi, 91):
            u = np.array([math.sin(angle), 0.0, math.cos(angle)])
            lobe = np.exp(k * (omega @ u - 1.0))
            flux = lobe * omega[:, 2]
            mean = (flux[:, None] * omega).sum(axis=0) / flux.sum()
            # The lobe's exitance over π, per unit of its peak, for the scale.
            grid.append((k, angle, mean[2], mean[0], flux.sum() * 2.0 / len(lobe)))
    grid = np.array(grid)
    column, row = np.meshgrid(np.arange(size), np.arange(size))
    sx = ((column + 0.5) / size * 2.0 - 1.0) * tan_half
    sy = (1.0 - (row + 0.5) / size * 2.0) * tan_half
    d = forward + sx[..., None] * right + sy[..., None] * up
    d = (d / np.linalg.norm(d, axis=2)[..., None]).reshape(-1, 3)
    b = d @ eye
    disc = b * b - (eye @ eye - radius * radius)
    normal = (eye + (-b - np.sqrt(np.maximum(disc, 0.0)))[:, None] * d) / radius
    m = exitance.reshape(-1)
    mean = moments.reshape(-1, 3) / np.maximum(m, 1e-300)[:, None]
    along = dot(mean, normal)
    tangent = mean - along[:, None] * normal
    across = np.linalg.norm(tangent, axis=1)
    tangent = tangent / np.maximum(across, 1e-12)[:, None]
    radiance = np.zeros(len(m))
    for start in range(0, len(m), 1024):
        part = slice(start, start + 1024)
        nearest = np.argmin((grid[None, :, 2] - along[part, None]) ** 2
                            + (grid[None, :, 3] - across[part, None]) ** 2, axis=1)
        k, angle, scale = grid[nearest, 0], grid[nearest, 1], grid[nearest, 4]
        u = np.cos(angle)[:, None] * normal[part] + np.sin(angle)[:, None] * tangent[part]
        radiance[part] = m[part] * np.exp(k * (dot(-d[part], u) - 1.0)) / scale
    return np.where((disc > 0) & (m > 0), radiance, 0.0).reshape(size, size)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_arguments(parser)
    parser.add_argument("--photons", type=int, default=2_000_000, help="photons per channel")
    parser.add_argument("--batch", type=int, default=250_000, help="photons walked at once")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--eta", type=float, default=1.0,
                        help="index of refraction of the ball (1: index-matched)")
    parser.add_argument("--connect-fraction", type=float, default=1.0,
                        help="connect to the eye at this random share of the collisions in "
                             "the half of the ball away from the eye, rising to all of them "
                             "nearest it, weighted by its inverse (0 < f <= 1: less cost per "
                             "photon, for media whose photons collide hundreds of times)")
    parser.add_argument("--part", choices=["all", "single", "grazing-entry", "lambertian-exit",
                                           "lobe-exit"],
                        default="all",
                        help="render only single scattering (each photon's first collision), "
                             "only the photons entering at incidence cosines below 0.3, or the "
                             "exact exitance given out by Lambert's law or by a lobe about its "
                             "mean exit direction (index-matched only)")
    parser.add_argument("--uniform", action="store_true",
                        help="a uniform environment of radiance 1 instead of the light")
    args = parser.parse_args()
    if args.mesh is not None:
        parser.error("this light tracer traces the ball's sphere only (--radius); a mesh's is "
                     "translucent_accuracy's (examples/common/translucent_light_tracer.rs) "
                     "or Mitsuba's (translucent_reference.py)")
    if not 0.0 < args.connect_fraction <= 1.0:
        parser.error("--connect-fraction must lie in (0, 1]")
    if not 1.0 <= args.eta <= 3.0:
        parser.error("--eta must lie in 1 – 3")
    if args.part in ("lambertian-exit", "lobe-exit") and args.eta != 1.0:
        parser.error(f"--part {args.part} is for an index-matched ball (--eta 1)")
    if args.radius <= 0 or args.size <= 0 or args.photons < 2 or args.batch <= 0:
        parser.error("--radius, --size and --batch must be positive, --photons at least 2")
    if not all(a >= 0 and s > 0 for a, s in zip(args.sigma_a, args.sigma_s)):
        parser.error("--sigma-a must be ≥ 0 and --sigma-s > 0 in every channel")
    if args.point_light is not None and (not args.point_light > args.radius or args.uniform):
        parser.error("--point-light takes a distance beyond the ball's radius, and not with --uniform")
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
    moments = np.zeros((2, args.size, args.size, 3, 3))
    start = time.time()
    for ch in range(3):
        # Per metre: the coefficients are per millimetre.
        sigma_t = 1000.0 * (args.sigma_a[ch] + args.sigma_s[ch])
        albedo = args.sigma_s[ch] / (args.sigma_a[ch] + args.sigma_s[ch])
        for k in range(batches):
            image, moment = trace_channel(sigma_t, albedo, args, camera, rng, batch)
            halves[k % 2, :, :, ch] += image
            moments[k % 2, :, :, ch] += moment
        print(f"channel {ch}: {time.time() - start:.0f} s", file=sys.stderr)
    halves /= batches // 2
    moments /= batches // 2
    image = halves.mean(axis=0)
    if args.part == "lobe-exit":
        lobes = lambda e, m: np.stack(
            [lobe_exit_radiance(e[..., c], m[..., c, :], camera, args.radius) for c in range(3)], axis=2)
        image = lobes(image, moments.mean(axis=0))
        halves = np.stack([lobes(halves[h], moments[h]) for h in range(2)])
    ball = image.sum(axis=2) > 0
    noise = np.abs(halves[0] - halves[1])[ball].sum() / max(2.0 * image[ball].sum(), 1e-30)
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    mi.Bitmap(image.astype(np.float32)).write(args.out)
    print(f"wrote {args.out}: {batches * batch} photons a channel in {time.time() - start:.0f} s, "
          f"noise (relative L1 of the halves' difference / 2) {noise:.4f}")


if __name__ == "__main__":
    sys.exit(main())
