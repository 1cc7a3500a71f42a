"""The measured Cornell box of `tessera bench cornell` in Mitsuba 3, for the tracer speed
comparison: the same geometry, Lambertian walls, one-sided ceiling lamp, camera, 256x256,
the same path length, on all of this machine's cores. Prints one line per variant: camera
paths per second (the fastest of RUNS renders, after one that compiles its kernels) and,
with --mse, the first variant's MSE (the mean over those renders, each with its own seed)
against a 1024-spp reference of its own.

    python mitsuba_cornell.py SPP RUNS [--mse] VARIANT...

Run by scripts/mitsuba-compare.sh, which installs Mitsuba; not part of the test suite.
"""

import math
import sys
import time

import drjit as dr
import mitsuba as mi

SIZE = 256
# Tessera's max depth 8 is bounces after the camera ray: 9 segments, Mitsuba's 9.
MAX_DEPTH = 9
# Tessera starts Russian roulette once a path has 3 bounces.
RR_DEPTH = 3


def scene_dict(spp):
    T = mi.ScalarTransform4f

    def diffuse(colour):
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": colour}}

    def wall(to_world, colour):
        # Double-sided, as Tessera's walls are.
        return {"type": "rectangle", "to_world": to_world,
                "bsdf": {"type": "twosided", "bsdf": diffuse(colour)}}

    def block(scale, angle, at):
        # Tessera's cube spans [-0.5, 0.5], Mitsuba's [-1, 1].
        to_world = (T().translate(at).rotate([0, 1, 0], math.degrees(angle))
                    @ T().scale([s / 2 for s in scale]))
        return {"type": "cube", "to_world": to_world,
                "bsdf": {"type": "twosided", "bsdf": diffuse(white)}}

    white, red, green = [0.73, 0.73, 0.73], [0.63, 0.065, 0.05], [0.14, 0.45, 0.091]
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_DEPTH, "rr_depth": RR_DEPTH},
        "sensor": {
            "type": "perspective",
            "fov": 39.3,
            "fov_axis": "y",
            "to_world": T().look_at(origin=[0, 1, 3.75], target=[0, 1, 0], up=[0, 1, 0]),
            "sampler": {"type": "multijitter", "sample_count": spp},
            "film": {"type": "hdrfilm", "width": SIZE, "height": SIZE,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        },
        "floor": wall(T().rotate([1, 0, 0], -90), white),
        "ceiling": wall(T().translate([0, 2, 0]) @ T().rotate([1, 0, 0], 90), white),
        "back": wall(T().translate([0, 1, -1]), white),
        "left": wall(T().translate([-1, 1, 0]) @ T().rotate([0, 1, 0], 90), red),
        "right": wall(T().translate([1, 1, 0]) @ T().rotate([0, 1, 0], -90), green),
        "lamp": {
            "type": "rectangle",
            "to_world": T().translate([0, 1.998, 0]) @ T().rotate([1, 0, 0], 90)
            @ T().scale([0.235, 0.19, 1]),
            "bsdf": diffuse([0.78] * 3),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [17, 12, 4]}},
        },
        "tall": block([0.6, 1.2, 0.6], 0.29, [-0.33, 0.6, -0.3]),
        "short": block([0.6, 0.6, 0.6], -0.3, [0.34, 0.3, 0.25]),
    }


def render(scene, spp, seed):
    image = mi.render(scene, spp=spp, seed=seed)
    dr.eval(image)
    dr.sync_thread()
    return image


def main():
    spp, runs = int(sys.argv[1]), int(sys.argv[2])
    with_mse = "--mse" in sys.argv[3:]
    variants = [a for a in sys.argv[3:] if a != "--mse"]
    for i, variant in enumerate(variants):
        mi.set_variant(variant)
        scene = mi.load_dict(scene_dict(spp))
        render(scene, spp, 0)  # compiles the kernels (the JIT variants), warms the caches
        best = float("inf")
        images = []
        for seed in range(1, runs + 1):
            start = time.perf_counter()
            images.append(render(scene, spp, seed))
            best = min(best, time.perf_counter() - start)
        paths = SIZE * SIZE * spp
        line = f"mitsuba {mi.__version__} {variant}: {spp} spp, {paths / best / 1e6:.3f} M paths/s (fastest of {runs}: {best:.3f} s)"
        if i == 0 and with_mse:
            reference = render(mi.load_dict(scene_dict(1024)), 1024, 1000)
            errors = [dr.mean(dr.square(im - reference).array)[0] for im in images]
            mean = sum(errors) / len(errors)
            line += f", MSE {mean:.4e} against its own 1024 spp (mean of {len(errors)} seeds)"
        print(line, flush=True)


if __name__ == "__main__":
    main()
