"""A scene's light map at the object's place, rendered with Mitsuba 3 in ffls's lat-long convention.

Mitsuba 3 has no spherical (equirectangular) sensor; this script registers one, ``latlong``, as
a Python plugin: pixel (i, j) of a 2H x H film looks along the direction of ffls's lat-long
texel (i, j) (GUIDE section 1: top row +Z, centre column +X, a quarter from the left +Y), from
the point ``origin`` (world frame, +Z up). Render the virtual scene without the object with it,
at the object's place, and give the EXR to ``ffls composite --lightmap``.

It also gives the ``to_world`` that makes Mitsuba's ``envmap`` emitter (whose own frame has +Y up
and the image centre at +Z) light a Z-up scene from an ffls/Blender/Poly Haven lat-long map::

    {"type": "envmap", "filename": "sky.exr", "to_world": ENVMAP_TO_WORLD}

Usage, from Python (``import mitsuba as mi; mi.set_variant("scalar_rgb")`` first)::

    from mitsuba_latlong import register, latlong_sensor, ENVMAP_TO_WORLD
    register()
    scene = mi.load_dict({"type": "scene", ..., "sensor": latlong_sensor(origin=(0, 0, 0.1), height=256)})
    mi.util.write_bitmap("scene_map.exr", mi.render(scene, spp=256))

or ``python scripts/mitsuba_latlong.py SCENE.xml OUT.exr --origin X,Y,Z --height H --spp N``
(the scene file's own sensor is replaced). Needs ``pip install mitsuba`` (``ffls[validate]``).
"""
from __future__ import annotations

import argparse
import math

import drjit as dr
import mitsuba as mi

#: ``to_world`` of Mitsuba's ``envmap`` emitter for a lat-long map in ffls's (Blender's) convention:
#: the emitter's +X, +Y, +Z (its texel u = 0.25, its top row, its centre column) go to world +Y, +Z, +X.
ENVMAP_TO_WORLD = [[0, 0, 1, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1]]


def _sensor_class():
    class LatLongSensor(mi.Sensor):
        """Equirectangular sensor at ``origin``: film (u, v) in [0, 1]^2 (v down) looks along
        ``(sin t cos p, sin t sin p, cos t)`` with ``t = pi v`` and ``p = pi (1 - 2 u)``."""

        def __init__(self, props):
            super().__init__(props)
            o = props.get("origin", mi.ScalarPoint3f(0, 0, 0))
            self.origin = mi.Point3f(o)

        def _direction(self, uv):
            theta = math.pi * uv.y
            phi = math.pi * (1.0 - 2.0 * uv.x)
            st = dr.sin(theta)
            return mi.Vector3f(st * dr.cos(phi), st * dr.sin(phi), dr.cos(theta))

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            wavelengths, weight = mi.sample_rgb_spectrum(mi.sample_shifted(sample1)) \
                if mi.is_spectral else ([], mi.Spectrum(1.0))
            return mi.Ray3f(self.origin, self._direction(sample2), time, wavelengths), weight

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
            return mi.RayDifferential3f(ray), weight

        def bbox(self):
            return mi.ScalarBoundingBox3f(mi.ScalarPoint3f(self.origin))

        def to_string(self):
            return f"LatLongSensor[origin={self.origin}]"

    return LatLongSensor


def register() -> None:
    """Register the ``latlong`` sensor plugin (once per process, after ``mi.set_variant``)."""
    cls = _sensor_class()
    mi.register_sensor("latlong", lambda props: cls(props))


def latlong_sensor(origin=(0.0, 0.0, 0.0), height: int = 256) -> dict:
    """The ``latlong`` sensor's dictionary: a 2H x H linear float film with a box filter."""
    return {"type": "latlong", "origin": mi.ScalarPoint3f(*(float(v) for v in origin)),
            "film": {"type": "hdrfilm", "width": 2 * int(height), "height": int(height),
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", help="Mitsuba 3 scene file (.xml)")
    ap.add_argument("out", help="output lat-long .exr")
    ap.add_argument("--origin", default="0,0,0", help="X,Y,Z of the object's place (world, +Z up)")
    ap.add_argument("--height", type=int, default=256)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--variant", default="scalar_rgb")
    a = ap.parse_args()
    mi.set_variant(a.variant)
    register()
    scene = mi.load_file(a.scene)
    origin = tuple(float(v) for v in a.origin.split(","))
    sensor = mi.load_dict(latlong_sensor(origin, a.height))
    mi.util.write_bitmap(a.out, mi.render(scene, sensor=sensor, spp=a.spp))


if __name__ == "__main__":
    main()
