#!/usr/bin/env python3
"""Random walks through an index-matched slab of isotropically scattering medium (thickness in
mean free paths, single-scattering albedo α), entered diffusely (cosine-distributed) or by a
normal beam through its top face — two facts the translucency transport rests on
(docs/translucent.md, "Solved in the object's shape"):

1. The diffusion field deep inside is that of a source `z_s` reduced mean free paths under the
   surface: the transmission T through a thick slab, against diffusion theory's
   `T = sinh(σ(z_s + z_b)) cosh(σ z_b) / sinh(σ(L + 2 z_b))` (σ = √(3(1 − α)), z_b = 2/3),
   solved for z_s. Jensen's dipole puts its source at 1; diffuse light's is ≈ 2/3
   (`SHAPE_SOURCE_DEPTH`).
2. The transmitted light leaves in the deep field's law `s(μ) = H(μ)/(1 − νμ)/N`
   (`diffusion::deep_exit_law`), limb-darkened, not Lambert's: the walks' exit radiance by
   exit cosine over the law, and over Lambert's.

    python3 tools/slab_walks.py [--walks 400000] [--albedo 0.999,0.9586,0.85]

Needs numpy. Not needed by the crate or its tests.
"""

import argparse
import math
import sys

import numpy as np


def hapke_h(alpha, mu):
    """Chandrasekhar's H in Hapke's 2002 closed form, as `diffusion::chandrasekhar_h`."""
    mu = np.clip(mu, 1e-9, 1.0)
    gamma = math.sqrt(1.0 - alpha)
    r0 = (1.0 - gamma) / (1.0 + gamma)
    return 1.0 / (1.0 - alpha * mu * (r0 + 0.5 * (1.0 - 2.0 * r0 * mu) * np.log((1.0 + mu) / mu)))


def deep_law(alpha, mu):
    """`diffusion::deep_exit_law` and `deep_exit_shape`: H(μ)/(1 − νμ), normalised."""
    nu = min(math.sqrt(3.0 * (1.0 - alpha)), 0.9)
    grid = (np.arange(512) + 0.5) / 512
    norm = 2.0 * np.mean(hapke_h(alpha, grid) / (1.0 - nu * grid) * grid)
    return hapke_h(alpha, mu) / (1.0 - nu * mu) / norm


def walk(thickness, alpha, walks, diffuse, rng):
    """Transmitted weight and the exit cosines (with weights) of the transmitted walks."""
    z = np.zeros(walks)
    w = np.sqrt(rng.random(walks)) if diffuse else np.ones(walks)
    weight = np.ones(walks)
    transmitted, cosines, weights = 0.0, [], []
    while len(z):
        z = z + (-np.log(1.0 - rng.random(len(z)))) * w
        out = z > thickness
        transmitted += weight[out].sum()
        cosines.append(w[out])
        weights.append(weight[out])
        keep = ~(out | (z < 0.0))
        z, weight = z[keep], weight[keep] * alpha
        w = 2.0 * rng.random(len(z)) - 1.0
        # Russian roulette below 1/20.
        low = weight < 0.05
        survive = ~low | (rng.random(len(z)) < 0.5)
        weight = np.where(low, 2.0 * weight, weight)
        z, w, weight = z[survive], w[survive], weight[survive]
    return transmitted / walks, np.concatenate(cosines), np.concatenate(weights)


def source_depth(transmission, thickness, alpha):
    """Diffusion theory's source depth (mean free paths) for a slab's transmission."""
    sigma, zb = math.sqrt(3.0 * (1.0 - alpha)), 2.0 / 3.0
    extrapolated = thickness + 2.0 * zb
    if sigma < 1e-6:
        return transmission * extrapolated - zb
    x = transmission * math.sinh(sigma * extrapolated) / math.cosh(sigma * zb)
    return math.asinh(x) / sigma - zb


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--walks", type=int, default=400_000)
    parser.add_argument("--albedo", default="0.999,0.9586,0.85")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    try:
        albedos = [float(a) for a in args.albedo.split(",")]
    except ValueError:
        parser.error("--albedo takes comma-separated numbers")
    if args.walks < 1000 or not all(0.5 < a <= 1.0 for a in albedos):
        parser.error("--walks must be at least 1000 and each --albedo in (0.5, 1]")
    rng = np.random.default_rng(args.seed)
    bins = np.linspace(0.0, 1.0, 11)
    centres = 0.5 * (bins[1:] + bins[:-1])
    for alpha in albedos:
        for thickness in (8.0, 15.0) if alpha > 0.9 else (6.0,):
            depths = {}
            for diffuse in (True, False):
                t, mu, wt = walk(thickness, alpha, args.walks, diffuse, rng)
                depths["diffuse" if diffuse else "normal beam"] = source_depth(t, thickness, alpha)
                if diffuse:
                    counts, _ = np.histogram(mu, bins, weights=wt)
                    radiance = counts / centres
                    radiance /= 2.0 * np.sum(radiance * centres) * 0.1
                    law = deep_law(alpha, centres)
                    over_law = radiance / law
                    over_lambert = radiance
            print(f"albedo {alpha}, {thickness:g} mean free paths: source depth "
                  + ", ".join(f"{k} {v:.3f}" for k, v in depths.items()))
            print(f"  exit radiance by cosine (0.05 … 0.95) over the deep law: {np.round(over_law, 3)}"
                  f" (worst {np.abs(over_law - 1).max():.3f})")
            print(f"  over Lambert's: {np.round(over_lambert, 3)}")


if __name__ == "__main__":
    sys.exit(main())
