"""A scene where a mirror differs from a blur, rendered by Mitsuba 3 (issue "A mirror is a mirror").

A square plate (normal +z) seen 65 degrees off its normal by a perspective camera, filling most of the frame,
under a sharp-edged rectangular area light placed where the plate reflects it toward the camera, in a dim
room (a constant environment). A smooth conductor shows the light's sharp image; a glossy lobe blurs it;
the haze of a polished surface is a faint glow around it.

`render(bsdf)` takes any Mitsuba BSDF (a dict for `mi.load_dict`, or an object from `mi.load_string`);
`reflected(reference)` is the mask of the pixels where a smooth conductor reflects the light;
`flip(reference, test, mask)` is the mean HDR-FLIP (NVIDIA's `flip_evaluator`) over the masked pixels.

`room=0.0` is ndfit's `window` scene (`ndfit render --scene window`): the same plate, camera and light in a
black room (no environment emitter at all, so emitter sampling draws only the light). Every pixel is then
plate. `window(bsdf, spp, sampler=..., seed=...)` renders it. `sampler` is any Mitsuba sampler
(`stratified` by default, `multijitter`, `independent`, ...) and `seed` the seed `mi.render` is given;
`scene_dict(...)` is the scene's description for `mi.load_dict` (fits/render_tolerance.py uses it).
"""

import math

import numpy as np

THETA_DEG = 65.0
WIDTH, HEIGHT = 160, 96
LIGHT_RADIANCE = 20.0
ROOM_RADIANCE = 0.02


def _mi():
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant("scalar_rgb")
    return mi


def scene(bsdf, spp=16, room=ROOM_RADIANCE, sampler="stratified"):
    """The scene with the plate's `bsdf` (a dict or a loaded BSDF), in a room of radiance `room`
    (0: no environment, ndfit's `window` scene), sampled by Mitsuba's `sampler`."""
    return _mi().load_dict(scene_dict(bsdf, spp, room=room, sampler=sampler))


def scene_dict(bsdf, spp=16, room=ROOM_RADIANCE, sampler="stratified"):
    """`scene`'s description, for `mi.load_dict` (Mitsuba's variant already set)."""
    import mitsuba as mi

    t = math.radians(THETA_DEG)
    cam = [0.0, -4.0 * math.sin(t), 4.0 * math.cos(t)]
    light = [0.0, 6.0 * math.sin(t), 6.0 * math.cos(t)]
    T = mi.ScalarTransform4f
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2, "hide_emitters": True},
        "sensor": {
            "type": "perspective",
            "fov": 32.0,
            "fov_axis": "x",
            "to_world": T().look_at(origin=cam, target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": WIDTH, "height": HEIGHT, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": sampler, "sample_count": spp, "seed": 1},
        },
        "plate": {"type": "rectangle", "to_world": T().scale([3.2, 3.2, 1.0]), "bsdf": bsdf},
        # The light faces the plate's centre; 2.4 x 1.2 m at 6 m: about 23 x 11 degrees, a window with sharp edges.
        "light": {
            "type": "rectangle",
            "to_world": T().look_at(origin=light, target=[0, 0, 0], up=[0, 0, 1]) @ T().scale([1.2, 0.6, 1.0]),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [LIGHT_RADIANCE] * 3}},
        },
    }
    if room > 0:
        d["room"] = {"type": "constant", "radiance": {"type": "rgb", "value": [room] * 3}}
    return d


def render(bsdf, spp=16, room=ROOM_RADIANCE, sampler="stratified", seed=0):
    """Linear RGB radiance, shape (HEIGHT, WIDTH, 3), float32 (`seed` is `mi.render`'s)."""
    mi = _mi()
    img = mi.render(scene(bsdf, spp, room=room, sampler=sampler), spp=spp, seed=seed)
    return np.array(img, dtype=np.float32)


def window(bsdf, spp=256, sampler="multijitter", seed=0):
    """ndfit's `window` scene (black room), linear RGB, shape (HEIGHT, WIDTH, 3), float32."""
    return render(bsdf, spp, room=0.0, sampler=sampler, seed=seed)


def conductor():
    """A smooth conductor with F = 1 (Mitsuba's `conductor`, material `none`)."""
    return {"type": "conductor", "material": "none"}


def reflected(reference):
    """The pixels where the smooth conductor's render shows the light (above a tenth of its radiance)."""
    return reference.mean(axis=2) > 0.1 * LIGHT_RADIANCE


def plate(reference):
    """The plate's pixels (the conductor's render reflects at least the room there; not for room 0,
    where every pixel is plate)."""
    return reference.mean(axis=2) > 0.5 * ROOM_RADIANCE


def flip(reference, test, mask):
    """Mean HDR-FLIP of `test` against `reference` over `mask`."""
    import flip_evaluator

    fmap, _, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(reference, np.float32), np.ascontiguousarray(test, np.float32), "HDR",
        inputsRGB=False, applyMagma=False, computeMeanError=True,
    )
    return float(fmap[..., 0][mask].mean())
