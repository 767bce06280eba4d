"""A built-in synthetic Free-form Light Stage scene, rendered with NumPy (no GL).

The scene is what the system of Masselus, Dutre and Anrys ("The Free-form Light Stage",
Eurographics Workshop on Rendering 2002) needs to be tested end to end: a fixed pinhole camera,
an object with diffuse and glossy parts on a grey (or black-velvet) table, and four white diffuse
spheres beside it whose shading gives each photograph's light direction. Every image is lit by
one small light; cast shadows and one bounce of light off the ground are rendered.

Scene (metres, world +Z up, scene centre at the origin)
    * ground plane z = 0, Lambertian, albedo ``ground_albedo`` (0 = the paper's black velvet);
    * a blue diffuse box pedestal, a glossy red sphere on it (Lambert + normalised Blinn-Phong
      lobe, ``(m + 8) / (8 pi) (n.h)^m``) and a leaning green capsule beside it;
    * four white Lambertian spheres (albedo 0.8) resting on the ground at the corners of a square;
    * an OpenCV pinhole camera in front (at -Y), looking toward +Y and down 30 degrees.

Radiometry
    A *distant* light of direction ``l`` gives unit irradiance at normal incidence, so image
    ``i`` of a distant-light capture is the basis image ``B_i`` of the architecture
    (``relit = sum_i w_i B_i``). A *near* light at position ``q`` is an isotropic point light
    (or a small spherical light, sampled with several points) of intensity ``I``; the irradiance
    it gives is ``I cos / r^2``. The default intensity ``I = |q|^2`` gives unit irradiance at the
    scene centre. The surface radiance is ``(kd / pi + f_spec) E``.

Bounce
    One bounce off the ground onto the object and spheres: the ground's radiance is
    ``albedo / pi * E_direct`` (with its cast shadows) and the irradiance it gives a point ``p`` is
    estimated once per pixel by stratified cosine-weighted Monte Carlo (fixed seed) whose rays
    hit the ground; the hits are binned into a coarse ground grid (plus far rings), giving a
    sparse matrix ``F`` (surface pixels x ground cells). Per light only ``E_direct`` at the cell
    centres is evaluated (with shadow rays) and ``E_bounce = F @ (albedo / pi * E_cells)``. The
    bounce light reflects diffusely (``kd / pi``). The ground receives no bounce light.

The oracle :func:`render_lightmap` renders the scene under a light map by summing distant-light
renders over a clustering of the map's texels; relighting a distant-light capture must converge
to it as the number of capture lights grows. See ``docs/synth.md`` for measured speed and error.
"""
from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ffls.io.capture import LIGHTS_FILE, Capture, Lights, save_capture, save_lights
from ffls.conventions import check_hemisphere, in_domain, normalize
from ffls.errors import InputError, atomic_output
from ffls.lightmaps.lightmap import as_samples
from ffls.synth.geometry import Box, Capsule, Ground, Material, Sphere, closest_hit, occluded
from ffls.synth.photo import PhotoSettings, develop, response_table, write_photo

__all__ = [
    "SynthScene",
    "LABEL_BACKGROUND",
    "LABEL_GROUND",
    "LABEL_OBJECT",
    "LABEL_SPHERE0",
    "GBuffer",
    "gbuffer",
    "pixel_labels",
    "sphere_mask",
    "sphere_pixel_radii",
    "sphere_silhouettes",
    "render_light",
    "render_lights",
    "render_lightmap",
    "cluster_lightmap",
    "stratified_directions",
    "write_synthetic_capture",
    "write_calibration_pair",
    "make_scene",
    "sphere_layout",
    "TRUTH_FILE",
    "RESPONSE_FILE",
    "SPHERE_MATERIALS",
    "GROUND_TEXTURES",
    "BACKGROUNDS",
    "LENSES",
    "LONG_LENS_FOV_DEG",
    "LIGHT_ANGULAR_RADIUS_DEG",
]

#: Labels of :func:`pixel_labels`: nothing hit, the ground, the object, then sphere k is ``LABEL_SPHERE0 + k``.
LABEL_BACKGROUND = -1
LABEL_GROUND = 0
LABEL_OBJECT = 1
LABEL_SPHERE0 = 2

#: Ground truth written beside ``capture.json`` by :func:`write_synthetic_capture`.
TRUTH_FILE = "truth.json"
#: The inverse response table a gamma-2.2 8-bit capture states in ``capture.json``.
RESPONSE_FILE = "response.npy"

_EPS = 1e-6  # ray-origin offset along the normal, metres

#: Materials of the calibration spheres (``SynthScene.sphere_materials``).
SPHERE_MATERIALS = ("matte", "grey", "mirror", "glossy_black")
#: Lambert albedo of a ``'grey'`` sphere (``'matte'`` uses ``SynthScene.sphere_albedo``, 0.8).
GREY_ALBEDO = 0.25
#: Reflectance of a ``'mirror'`` (chrome) sphere, the same at every angle; it has no diffuse part.
CHROME_REFLECTANCE = 0.9
#: A ``'glossy_black'`` sphere: diffuse albedo, and the normal-incidence reflectance of its Schlick-Fresnel mirror coat.
BLACK_ALBEDO, BLACK_COAT_F0 = 0.03, 0.04
#: Ground textures (``SynthScene.ground_texture``).
GROUND_TEXTURES = ("none", "blotchy", "checker")
#: Default angular radius (degrees) of a distant light as mirrors see it (the sun's is 0.27).
LIGHT_ANGULAR_RADIUS_DEG = 0.5
_MIRROR_SUB = 16  # sub-rays per side of a pixel near a mirror highlight (at least)


def _value_noise(q, seed: int) -> np.ndarray:
    """Smooth value noise in [0, 1] at points (n, 2): hashed lattice values, smoothstep-blended."""
    i = np.floor(q)
    f = q - i
    f = f * f * (3.0 - 2.0 * f)

    def h(di, dj):
        x = np.sin((i[:, 0] + di) * 127.1 + (i[:, 1] + dj) * 311.7 + seed * 74.7) * 43758.5453
        return x - np.floor(x)

    a, b, c, d = h(0, 0), h(1, 0), h(0, 1), h(1, 1)
    return (a * (1 - f[:, 0]) + b * f[:, 0]) * (1 - f[:, 1]) + (c * (1 - f[:, 0]) + d * f[:, 0]) * f[:, 1]


# ============================================================================ scene description
@dataclass(frozen=True)
class SynthScene:
    """Layout of the synthetic scene; frozen and hashable (it keys the G-buffer cache).

    Parameters
    ----------
    sphere_radius : float
        Radius of the four white spheres (m). They rest on the ground: centre z = radius.
    sphere_xy : tuple of 4 (x, y)
        Ground positions of the sphere centres (m). Default: corners of a 0.5 m square.
    sphere_albedo : float
        Lambertian albedo of the white spheres.
    ground_albedo : float
        Lambertian albedo of the ground plane (0 = black velvet).
    camera_distance : float
        Distance from the camera centre to ``camera_target`` (m).
    camera_elevation_deg : float
        How far the camera looks down, degrees (the camera sits at -Y, raised).
    camera_roll_deg : float
        The camera turned about its optical axis, degrees: a tripod that is not level. Positive
        dips the image's right (the camera's x axis turns toward its y, down), so the world's
        vertical leans counter-clockwise in the image. 0: image right is level.
    camera_fov_deg : float
        Horizontal (and vertical: square pixels, square images) field of view, degrees.
    camera_target : tuple of 3
        World point on the optical axis (m).
    bounce_samples : int
        Monte Carlo rays per surface pixel for the ground bounce (rounded up to a square).
    ground_cells : int
        Cells per side of the ground grid that carries the bounce light.
    ground_extent : float
        Half side of that grid (m); ground beyond it is binned into far rings.
    supersample : int
        Primary rays per pixel along each axis (box filter); 1 = one ray through each pixel centre.
    seed : int
        Seed of the bounce sampling (the output is deterministic).

    Notes
    -----
    The defaults put the spheres at about 45 px radius at 768 x 768 (52 px for the front pair,
    36 px for the back pair) and keep everything inside the frame at any resolution.
    """

    sphere_radius: float = 0.05
    sphere_xy: tuple = ((-0.25, -0.25), (0.25, -0.25), (0.25, 0.25), (-0.25, 0.25))
    sphere_albedo: float = 0.8
    ground_albedo: float = 0.3
    camera_distance: float = 1.0
    camera_elevation_deg: float = 30.0
    camera_roll_deg: float = 0.0
    camera_fov_deg: float = 46.0
    camera_target: tuple = (0.0, 0.0, 0.05)
    bounce_samples: int = 64
    ground_cells: int = 128
    ground_extent: float = 1.0
    supersample: int = 1
    seed: int = 0
    sphere_materials: tuple = "matte"
    with_object: bool = True
    ground_texture: str = "none"
    texture_scale: float = 0.04
    camera_model: str = "pinhole"

    def __post_init__(self):
        object.__setattr__(self, "sphere_xy", tuple(tuple(float(v) for v in p) for p in self.sphere_xy))
        object.__setattr__(self, "camera_target", tuple(float(v) for v in self.camera_target))
        if any(len(p) != 2 for p in self.sphere_xy):
            raise ValueError("sphere_xy must be a sequence of (x, y) ground positions")
        mats = self.sphere_materials
        n = len(self.sphere_xy)
        if isinstance(mats, str):
            mats = (tuple(SPHERE_MATERIALS[k % len(SPHERE_MATERIALS)] for k in range(n)) if mats == "mixed"
                    else (mats,) * n)
        mats = tuple(mats)
        if len(mats) != n or any(m not in SPHERE_MATERIALS for m in mats):
            raise ValueError(f"sphere_materials: one of {SPHERE_MATERIALS} (or 'mixed') for all spheres, or one "
                             f"per sphere ({n}), not {self.sphere_materials!r}")
        object.__setattr__(self, "sphere_materials", mats)
        if self.sphere_radius <= 0 or self.camera_distance <= 0 or not 0 < self.camera_fov_deg < 180:
            raise ValueError("sphere_radius and camera_distance must be > 0 and 0 < fov < 180")
        if self.supersample < 1 or self.bounce_samples < 1 or self.ground_cells < 1:
            raise ValueError("supersample, bounce_samples and ground_cells must be >= 1")
        if self.ground_texture not in GROUND_TEXTURES or not self.texture_scale > 0:
            raise ValueError(f"ground_texture must be one of {GROUND_TEXTURES} and texture_scale > 0")
        if self.camera_model not in ("pinhole", "orthographic"):
            raise ValueError("camera_model must be 'pinhole' or 'orthographic'")

    # ------------------------------------------------------------------ derived quantities
    @property
    def sphere_centers(self) -> np.ndarray:
        """(n, 3) float64 sphere centres (m), resting on the ground."""
        return np.array([[x, y, self.sphere_radius] for x, y in self.sphere_xy], dtype=np.float64).reshape(-1, 3)

    @property
    def n_spheres(self) -> int:
        return len(self.sphere_xy)

    def metres_per_pixel(self, resolution: int) -> float:
        """Pixel pitch of the orthographic camera (m): it sees the width ``2 D tan(fov / 2)`` of a
        pinhole at ``camera_distance`` at its target."""
        return 2.0 * self.camera_distance * math.tan(math.radians(self.camera_fov_deg) / 2) / int(resolution)

    def project(self, points, resolution: int) -> np.ndarray:
        """(n, 2) pixel coordinates (u, v) of world points (n, 3), OpenCV pixel-centre convention."""
        M = self.world_from_camera()
        c = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - M[:3, 3]) @ M[:3, :3]
        if self.camera_model == "orthographic":
            return c[:, :2] / self.metres_per_pixel(resolution) + 0.5 * (int(resolution) - 1)
        K = self.K(resolution)
        return (c @ K.T)[:, :2] / c[:, 2:3]

    def camera_center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates (m)."""
        e = math.radians(self.camera_elevation_deg)
        return np.asarray(self.camera_target) + self.camera_distance * np.array([0.0, -math.cos(e), math.sin(e)])

    def world_from_camera(self) -> np.ndarray:
        """(4, 4) rigid transform, OpenCV camera axes (x right, y down, z forward) to world."""
        c = self.camera_center()
        f = normalize(np.asarray(self.camera_target) - c)
        x = normalize(np.cross(f, [0.0, 0.0, 1.0]))
        y = np.cross(f, x)
        r = math.radians(self.camera_roll_deg)
        x, y = math.cos(r) * x + math.sin(r) * y, math.cos(r) * y - math.sin(r) * x
        M = np.eye(4)
        M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = x, y, f, c
        return M

    def K(self, resolution: int) -> np.ndarray:
        """(3, 3) intrinsics for a ``resolution`` x ``resolution`` image (pinhole camera only).

        OpenCV convention: pixel (u, v) = (column, row) has its centre at integer coordinates,
        so the principal point is ((W - 1) / 2, (H - 1) / 2).
        """
        if self.camera_model != "pinhole":
            raise ValueError("an orthographic camera has no K (use metres_per_pixel)")
        f = 0.5 * resolution / math.tan(math.radians(self.camera_fov_deg) / 2)
        c = 0.5 * (resolution - 1)
        return np.array([[f, 0.0, c], [0.0, f, c], [0.0, 0.0, 1.0]])

    def sphere_material(self, k: int) -> Material:
        """The :class:`~ffls.synth.geometry.Material` of sphere ``k``."""
        name = self.sphere_materials[k]
        if name == "matte":
            return Material((self.sphere_albedo,) * 3)
        if name == "grey":
            return Material((GREY_ALBEDO,) * 3)
        if name == "mirror":
            return Material((0.0, 0.0, 0.0), mirror=CHROME_REFLECTANCE)
        return Material((BLACK_ALBEDO,) * 3, mirror=BLACK_COAT_F0, fresnel=True)

    def primitives(self) -> list:
        """The scene's primitives: ground, pedestal, glossy body, capsule (if ``with_object``), then the spheres."""
        prims = [Ground(Material((self.ground_albedo,) * 3), LABEL_GROUND)]
        if self.with_object:
            prims += [
                Box((-0.09, -0.09, 0.0), (0.09, 0.09, 0.05), Material((0.12, 0.22, 0.55)), LABEL_OBJECT),
                Sphere((0.0, 0.0, 0.135), 0.085, Material((0.55, 0.10, 0.07), ks=0.3, shininess=50.0), LABEL_OBJECT),
                Capsule((0.15, -0.08, 0.025), (0.10, 0.02, 0.19), 0.025,
                         Material((0.20, 0.50, 0.12), ks=0.08, shininess=20.0), LABEL_OBJECT),
            ]
        for k, c in enumerate(self.sphere_centers):
            prims.append(Sphere(tuple(c), self.sphere_radius, self.sphere_material(k), LABEL_SPHERE0 + k))
        return prims

    def reach(self) -> float:
        """The largest distance (m) from the scene centre (the origin) of a point of the object or a
        sphere: a near light must be farther away to light the scene from outside it."""
        r = 0.0
        for p in self.primitives():
            if isinstance(p, Sphere):
                r = max(r, float(np.linalg.norm(p.center)) + p.radius)
            elif isinstance(p, Box):
                r = max(r, float(np.linalg.norm(np.maximum(np.abs(p.lo), np.abs(p.hi)))))
            elif isinstance(p, Capsule):
                r = max(r, max(float(np.linalg.norm(p.a)), float(np.linalg.norm(p.b))) + p.radius)
        return r

    def ground_albedo_at(self, xy) -> np.ndarray:
        """(n,) albedo of the ground at points (n, 2) (m): ``ground_albedo``, or its texture.

        ``'blotchy'``: two octaves of value noise (cell ``texture_scale``), pushed through a steep
        tanh into high-contrast blotches, albedo ``ground_albedo * (0.1 .. 1.9)``;
        ``'checker'``: squares of side ``texture_scale`` of ``0.2`` and ``1.8 * ground_albedo``.
        Either way the mean albedo is about ``ground_albedo``.
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        a = self.ground_albedo
        if self.ground_texture == "none":
            return np.full(len(xy), float(a))
        q = xy / self.texture_scale
        if self.ground_texture == "checker":
            t = (np.floor(q[:, 0]) + np.floor(q[:, 1])) % 2
            return a * (0.2 + 1.6 * t)
        n = 0.65 * _value_noise(q, self.seed) + 0.35 * _value_noise(2.03 * q + 17.0, self.seed + 1)
        t = 0.5 + 0.5 * np.tanh(8.0 * (n - 0.5))
        return a * (0.1 + 1.8 * t)


# ============================================================================ conditions
#: Backgrounds of :func:`make_scene`: keyword arguments of :class:`SynthScene`.
BACKGROUNDS = {
    "black": {"ground_albedo": 0.0},
    "grey": {"ground_albedo": 0.3},
    "white": {"ground_albedo": 0.8},
    "textured": {"ground_albedo": 0.3, "ground_texture": "blotchy"},
}
#: Field of view of the long lens: 10 m away, it frames what the normal lens frames at 1 m.
LONG_LENS_FOV_DEG = 2.0 * math.degrees(math.atan(math.tan(math.radians(23.0)) / 10.0))
#: Lenses of :func:`make_scene`: keyword arguments of :class:`SynthScene`.
LENSES = {
    "normal": {},
    "long": {"camera_distance": 10.0, "camera_fov_deg": LONG_LENS_FOV_DEG},
    "orthographic": {"camera_model": "orthographic", "camera_distance": 10.0, "camera_fov_deg": LONG_LENS_FOV_DEG},
}


def sphere_layout(n: int, ring: float | None = None) -> tuple:
    """Ground positions (x, y) of ``n`` spheres evenly on a circle around the object.

    The first sits front-left (azimuth -135 degrees) and the others follow counter-clockwise;
    ``n = 4`` gives the default corners of a 0.5 m square. The ring radius is 0.354 m up to 4
    spheres and 0.3 m beyond (so that side spheres stay in frame).
    """
    n = int(n)
    if n < 0:
        raise ValueError("the number of spheres must be >= 0")
    if ring is None:
        ring = math.sqrt(0.125) if n <= 4 else 0.3
    a = np.radians(-135.0 + 360.0 * np.arange(n) / max(n, 1))
    return tuple((round(float(ring * math.cos(t)), 12), round(float(ring * math.sin(t)), 12)) for t in a)


def make_scene(spheres: int = 4, sphere_material="matte", background: str = "grey", lens: str = "normal",
               with_object: bool = True, sphere_xy=None, **kwargs) -> SynthScene:
    """A :class:`SynthScene` for named conditions.

    Parameters
    ----------
    spheres : int
        Number of spheres on :func:`sphere_layout` (ignored when ``sphere_xy`` is given).
    sphere_material : str or sequence of str
        One of :data:`SPHERE_MATERIALS`, ``'mixed'`` (cycling through them), or one per sphere.
    background : {'black', 'grey', 'white', 'textured'}
        See :data:`BACKGROUNDS`.
    lens : {'normal', 'long', 'orthographic'}
        See :data:`LENSES`.
    with_object : bool
    sphere_xy : sequence of (x, y), optional
    **kwargs
        Other :class:`SynthScene` fields (``sphere_radius``, ``supersample``, ...).
    """
    if background not in BACKGROUNDS:
        raise ValueError(f"background must be one of {tuple(BACKGROUNDS)}, not {background!r}")
    if lens not in LENSES:
        raise ValueError(f"lens must be one of {tuple(LENSES)}, not {lens!r}")
    xy = sphere_layout(spheres) if sphere_xy is None else tuple(sphere_xy)
    kw = {**BACKGROUNDS[background], **LENSES[lens], **kwargs}
    return SynthScene(sphere_xy=xy, sphere_materials=sphere_material, with_object=with_object, **kw)


# ============================================================================ G-buffer
@dataclass
class GBuffer:
    """Primary hits of one (scene, resolution), computed once and cached.

    Attributes
    ----------
    shape : (Hs, Ws)
        Supersampled image shape (``resolution * supersample`` per side).
    points, normals, view : (P, 3) float64
        World position, unit normal and unit direction to the camera of every hit sample.
    index : (P,) int64
        Flat index into the supersampled image of each hit sample.
    prim : (P,) int64
        Index into ``scene.primitives()`` of the primitive hit.
    labels : (Hs, Ws) int8
        :data:`LABEL_GROUND`, :data:`LABEL_OBJECT`, ``LABEL_SPHERE0 + k`` or :data:`LABEL_BACKGROUND`.
    kd : (P, 3), ks : (P,), shininess : (P,)
        Material of each hit sample (``kd`` of the ground is its texture there).
    mirror_idx : (M,) int64
        Indices (into the P hits) of the hits on a mirror-coated sphere.
    mirror_F : (M,) float64
        Reflectance of the coat there (Schlick's Fresnel term at the viewing angle, or constant).
    refl_dir : (M, 3) float64
        Reflected viewing ray (unit).
    refl_hit : (M,) bool
        Whether the reflected ray hits the scene (else it leaves it).
    refl_t, refl_points, refl_normals, refl_kd
        Distance, point, normal and Lambert albedo of those secondary hits ((M,), (M, 3) x 3).
    refl_footprint : (M,) float64
        Largest angle (radians) between the reflected ray of the pixel centre and those of its
        corners (pi where a corner misses the sphere): where a light can show in the pixel.
    cell_albedo : (C,) float64
        Ground albedo at the bounce cells.
    """

    shape: tuple
    points: np.ndarray
    normals: np.ndarray
    view: np.ndarray
    index: np.ndarray
    prim: np.ndarray
    labels: np.ndarray
    kd: np.ndarray
    ks: np.ndarray
    shininess: np.ndarray
    bounce: sp.csr_matrix = field(default=None, repr=False)  # (P, C) or None
    cell_points: np.ndarray = field(default=None, repr=False)  # (C, 3)
    mirror_idx: np.ndarray = field(default=None, repr=False)
    mirror_F: np.ndarray = field(default=None, repr=False)
    refl_dir: np.ndarray = field(default=None, repr=False)
    refl_hit: np.ndarray = field(default=None, repr=False)
    refl_t: np.ndarray = field(default=None, repr=False)
    refl_points: np.ndarray = field(default=None, repr=False)
    refl_normals: np.ndarray = field(default=None, repr=False)
    refl_kd: np.ndarray = field(default=None, repr=False)
    refl_footprint: np.ndarray = field(default=None, repr=False)
    cell_albedo: np.ndarray = field(default=None, repr=False)


def _rays_through(scene: SynthScene, resolution: int, u, v):
    """World rays (o, d) (n, 3) through pixel coordinates ``u``, ``v`` (n,) of the camera."""
    M = scene.world_from_camera()
    u = np.asarray(u, dtype=np.float64).ravel()
    v = np.asarray(v, dtype=np.float64).ravel()
    if scene.camera_model == "orthographic":
        s = scene.metres_per_pixel(resolution)
        c = 0.5 * (resolution - 1)
        d = np.broadcast_to(M[:3, 2], (len(u), 3)).copy()
        # origins on the image plane, well outside the scene (parallel rays: the distance is free)
        back = M[:3, 3] - 10.0 * M[:3, 2]
        o = back + np.outer((u - c) * s, M[:3, 0]) + np.outer((v - c) * s, M[:3, 1])
        return o, d
    K = scene.K(resolution)
    x = (u - K[0, 2]) / K[0, 0]
    y = (v - K[1, 2]) / K[1, 1]
    dc = np.stack([x, y, np.ones(x.size)], axis=1)
    d = normalize(dc @ M[:3, :3].T)
    o = np.broadcast_to(M[:3, 3], d.shape).copy()
    return o, d


def _sample_uv(scene: SynthScene, resolution: int, flat_index):
    """(u, v) pixel coordinates of the supersampled samples ``flat_index`` (row-major, n = resolution * supersample)."""
    s = scene.supersample
    n = resolution * s
    row, col = np.divmod(np.asarray(flat_index, dtype=np.int64), n)
    return (col + 0.5) / s - 0.5, (row + 0.5) / s - 0.5


def _primary_rays(scene: SynthScene, resolution: int):
    n = resolution * scene.supersample
    u, v = _sample_uv(scene, resolution, np.arange(n * n))
    o, d = _rays_through(scene, resolution, u, v)
    return o, d, (n, n)


@functools.lru_cache(maxsize=4)
def gbuffer(scene: SynthScene, resolution: int) -> GBuffer:
    """The cached primary-hit buffer of ``scene`` at ``resolution`` x ``resolution``.

    The bounce form-factor matrix is built here too (static geometry): the first call costs
    about 0.3 s at 256 x 256 and 5 s at 768 x 768; later calls are free. The returned object is
    shared by every caller (an LRU cache of 4 entries): do not modify its arrays.

    Parameters
    ----------
    scene : SynthScene
    resolution : int
        Image width and height (pixels), before supersampling.

    Returns
    -------
    GBuffer
    """
    if int(resolution) < 1:
        raise ValueError("resolution must be >= 1")
    prims = scene.primitives()
    o, d, shape = _primary_rays(scene, int(resolution))
    t, idx = closest_hit(prims, o, d)
    hit = idx >= 0
    index = np.flatnonzero(hit)
    pid = idx[hit]
    p = o[hit] + t[hit, None] * d[hit]
    n = np.zeros_like(p)
    labels = np.full(shape[0] * shape[1], LABEL_BACKGROUND, dtype=np.int8)
    kd = np.zeros_like(p)
    ks = np.zeros(len(p))
    sh = np.ones(len(p))
    mir = np.zeros(len(p))
    fres = np.zeros(len(p), dtype=bool)
    for k, prim in enumerate(prims):
        m = pid == k
        if not m.any():
            continue
        n[m] = prim.normal(p[m])
        labels[index[m]] = prim.label
        kd[m] = prim.material.kd
        ks[m] = prim.material.ks
        sh[m] = prim.material.shininess
        mir[m] = prim.material.mirror
        fres[m] = prim.material.fresnel
    # the ground is exactly z = 0 where hit
    g = labels[index] == LABEL_GROUND
    p[g, 2] = 0.0
    if scene.ground_texture != "none" and g.any():
        kd[g] = scene.ground_albedo_at(p[g, :2])[:, None]
    gb = GBuffer(shape=shape, points=p, normals=normalize(n), view=-d[hit], index=index, prim=pid,
                 labels=labels.reshape(shape), kd=kd, ks=ks, shininess=sh)
    gb.bounce, gb.cell_points = _bounce_matrix(scene, prims, gb)
    G = scene.ground_cells
    gb.cell_albedo = np.full(len(gb.cell_points), float(scene.ground_albedo))
    gb.cell_albedo[:G * G] = scene.ground_albedo_at(gb.cell_points[:G * G, :2])
    _mirror_buffers(scene, prims, gb, mir, fres, int(resolution))
    return gb


def _surface_at(scene: SynthScene, prims, p, pid):
    """Unit normals (n, 3) and Lambert albedo (n, 3) at hit points ``p`` of primitives ``pid``."""
    n = np.zeros_like(p)
    kd = np.zeros_like(p)
    for k, prim in enumerate(prims):
        m = pid == k
        if m.any():
            n[m] = prim.normal(p[m])
            kd[m] = prim.material.kd
            if isinstance(prim, Ground):
                p[m, 2] = 0.0
                kd[m] = scene.ground_albedo_at(p[m, :2])[:, None]
    return normalize(n), kd


def _reflect(view, n):
    """Mirror direction (unit) of the viewing ray ``-view`` about unit normals ``n``."""
    return normalize(2.0 * np.einsum("ij,ij->i", view, n)[:, None] * n - view)


def _mirror_buffers(scene: SynthScene, prims, gb: GBuffer, mirror, fresnel, resolution: int):
    """Fill the ``mirror_*`` and ``refl_*`` fields of ``gb`` (static reflected rays of mirror-coated hits)."""
    mi = np.flatnonzero(mirror > 0)
    gb.mirror_idx = mi
    nrm, v = gb.normals[mi], gb.view[mi]
    cos = np.clip(np.einsum("ij,ij->i", nrm, v), 0.0, 1.0)
    F0 = mirror[mi]
    gb.mirror_F = np.where(fresnel[mi], F0 + (1.0 - F0) * (1.0 - cos) ** 5, F0)
    r = _reflect(v, nrm)
    gb.refl_dir = r
    o2 = gb.points[mi] + _EPS * nrm
    t2, id2 = closest_hit(prims, o2, r)
    hit = id2 >= 0
    gb.refl_hit, gb.refl_t = hit, t2
    p2 = o2[hit] + t2[hit, None] * r[hit]
    gb.refl_normals, gb.refl_kd = _surface_at(scene, prims, p2, id2[hit])
    gb.refl_points = p2
    # footprint: reflected rays through the (supersampled) pixel's corners, on the same sphere
    foot = np.zeros(len(mi))
    if len(mi):
        u, vv = _sample_uv(scene, resolution, gb.index[mi])
        h = 0.5 / scene.supersample
        worst = np.zeros(len(mi))
        for du, dv in ((-h, -h), (h, -h), (-h, h), (h, h)):
            o, d = _rays_through(scene, resolution, u + du, vv + dv)
            t0 = np.full(len(mi), np.inf)
            for k in np.unique(gb.prim[mi]):
                m = gb.prim[mi] == k
                t0[m] = prims[k].interval(o[m], d[m])[0]
            ok = np.isfinite(t0)
            rc = np.zeros_like(d)
            if ok.any():
                pc = o[ok] + t0[ok, None] * d[ok]
                nc = np.zeros_like(pc)
                for k in np.unique(gb.prim[mi][ok]):
                    m = gb.prim[mi][ok] == k
                    nc[m] = prims[k].normal(pc[m])
                rc[ok] = _reflect(-d[ok], nc)
            ang = np.arccos(np.clip(np.einsum("ij,ij->i", rc, r), -1.0, 1.0))
            worst = np.where(ok, np.maximum(worst, ang), np.pi)  # a corner off the sphere: anywhere
        foot = worst
    gb.refl_footprint = foot


# ============================================================================ bounce
def _concentric(u1, u2):
    """Shirley-Chiu concentric map of the unit square onto the unit disk."""
    a, b = 2 * u1 - 1, 2 * u2 - 1
    first = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(first, a, b)
        phi = np.where(first, (np.pi / 4) * (b / a), np.pi / 2 - (np.pi / 4) * (a / b))
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def _frame(n):
    """Orthonormal tangents (t, b) for unit normals (n, 3) (Duff et al. 2017)."""
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bb = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bb


_N_RINGS, _N_AZ, _RING_MAX = 12, 32, 256.0


def _cell_of(scene: SynthScene, x):
    """Ground cell index of ground points (n, 2): grid cells, then log-radius x azimuth rings."""
    G, E = scene.ground_cells, scene.ground_extent
    i = np.floor((x[:, 0] + E) / (2 * E) * G).astype(np.int64)
    j = np.floor((x[:, 1] + E) / (2 * E) * G).astype(np.int64)
    inside = (i >= 0) & (i < G) & (j >= 0) & (j < G)
    r = np.maximum(np.abs(x[:, 0]), np.abs(x[:, 1]))
    ring = np.clip(np.floor(np.log(np.maximum(r, E) / E) / np.log(_RING_MAX) * _N_RINGS), 0, _N_RINGS - 1).astype(np.int64)
    az = np.floor((np.arctan2(x[:, 1], x[:, 0]) + np.pi) / (2 * np.pi) * _N_AZ).astype(np.int64) % _N_AZ
    return np.where(inside, j * G + i, G * G + ring * _N_AZ + az)


def _bounce_matrix(scene: SynthScene, prims, gb: GBuffer, chunk: int = 400_000):
    """Sparse (P, C) matrix F with E_bounce(p) = sum_c F[p, c] L_ground(c); and cell points (C, 3)."""
    G = scene.ground_cells
    C = G * G + _N_RINGS * _N_AZ
    E = scene.ground_extent
    c = (np.arange(G) + 0.5) / G * 2 * E - E
    cx, cy = np.meshgrid(c, c)
    grid_pts = np.stack([cx.ravel(), cy.ravel(), np.zeros(G * G)], axis=1)
    surf = np.flatnonzero((gb.labels.ravel()[gb.index] > LABEL_GROUND) & (gb.kd.max(axis=1) > 0))
    P = len(gb.points)
    k = int(math.ceil(math.sqrt(scene.bounce_samples)))
    S = k * k
    if len(surf) == 0:
        return sp.csr_matrix((P, C), dtype=np.float64), np.concatenate([grid_pts, np.zeros((C - G * G, 3))])
    rng = np.random.default_rng(scene.seed)
    occ_prims = [p for p in prims if not isinstance(p, Ground)]
    rows, cols, hits = [], [], []
    per = max(1, chunk // S)
    for s0 in range(0, len(surf), per):
        ids = surf[s0:s0 + per]
        m = len(ids)
        si, sj = np.meshgrid(np.arange(k), np.arange(k))
        u1 = (si.ravel()[None, :] + rng.random((m, S))) / k
        u2 = (sj.ravel()[None, :] + rng.random((m, S))) / k
        dx, dy = _concentric(u1, u2)
        dz = np.sqrt(np.maximum(0.0, 1 - dx * dx - dy * dy))
        n = gb.normals[ids]
        t, b = _frame(n)
        d = (dx[..., None] * t[:, None] + dy[..., None] * b[:, None] + dz[..., None] * n[:, None]).reshape(-1, 3)
        o = np.repeat(gb.points[ids] + _EPS * n, S, axis=0)
        row = np.repeat(ids, S)
        down = d[:, 2] < -1e-9
        o, d, row = o[down], d[down], row[down]
        tg = -o[:, 2] / d[:, 2]
        vis = ~occluded(occ_prims, o, d, tg)
        x = o[vis] + tg[vis, None] * d[vis]
        rows.append(row[vis])
        cols.append(_cell_of(scene, x[:, :2]))
        hits.append(x)
    rows = np.concatenate(rows)
    cols = np.concatenate(cols)
    x = np.concatenate(hits)
    F = sp.csr_matrix((np.full(len(rows), np.pi / S), (rows, cols)), shape=(P, C))
    # representative point of each ring cell: the mean of its hits (radius clipped); grid: centres
    ring_pts = np.zeros((C - G * G, 3))
    rc = cols >= G * G
    if rc.any():
        cnt = np.bincount(cols[rc] - G * G, minlength=C - G * G)
        for ax in (0, 1):
            ring_pts[:, ax] = np.bincount(cols[rc] - G * G, weights=x[rc, ax], minlength=C - G * G) / np.maximum(cnt, 1)
    r = np.linalg.norm(ring_pts[:, :2], axis=1, keepdims=True)
    ring_pts[:, :2] *= np.minimum(1.0, _RING_MAX * E / np.maximum(r, 1e-12))
    return F, np.concatenate([grid_pts, ring_pts])


# ============================================================================ shading
def _light_samples(direction, position, intensity, radius, n_samples):
    """A light as a list of (direction or None, position or None, weight)."""
    if (direction is None) == (position is None):
        raise ValueError("give exactly one of direction= or position=")
    if direction is not None:
        dvec = np.asarray(direction, dtype=np.float64).reshape(3)
        if not np.isfinite(dvec).all() or np.linalg.norm(dvec) == 0:
            raise ValueError("direction must be a finite non-zero 3-vector")
        return [(normalize(dvec), None, 1.0)]
    q = np.asarray(position, dtype=np.float64).reshape(3)
    I = float(q @ q) if intensity is None else float(intensity)
    if radius <= 0 or n_samples <= 1:
        return [(None, q, I)]
    # stratified points on the disk of the spherical light facing the scene centre
    w = normalize(-q)
    t, b = _frame(w[None])
    k = int(math.ceil(math.sqrt(n_samples)))
    g = (np.arange(k) + 0.5) / k
    u1, u2 = np.meshgrid(g, g)
    dx, dy = _concentric(u1.ravel(), u2.ravel())
    pts = q + radius * (dx[:, None] * t + dy[:, None] * b)
    return [(None, p, I / len(pts)) for p in pts]


def _emitter(direction, position, intensity, radius, angular_radius_deg):
    """The light as mirrors see it: a disc of directions (distant) or a sphere (near), uniform radiance.

    A distant light of angular radius ``theta`` has radiance ``1 / (pi sin^2 theta)``, so its
    irradiance at normal incidence stays 1. A near light of intensity ``I`` is a sphere of radius
    ``radius`` (or, for a point light, the radius that subtends ``angular_radius_deg`` from the
    scene centre) of radiance ``I / (pi radius^2)``.
    """
    th = math.radians(float(angular_radius_deg))
    if not 0 < th < math.pi / 2:
        raise ValueError(f"light_angular_radius_deg must be in (0, 90), not {angular_radius_deg}")
    if direction is not None:
        return {"kind": "distant", "l": normalize(np.asarray(direction, dtype=np.float64).reshape(3)),
                "theta": th, "L": 1.0 / (np.pi * math.sin(th) ** 2)}
    q = np.asarray(position, dtype=np.float64).reshape(3)
    I = float(q @ q) if intensity is None else float(intensity)
    a = float(radius) if radius > 0 else float(np.linalg.norm(q)) * math.tan(th)
    return {"kind": "near", "q": q, "a": a, "L": I / (np.pi * a * a)}


def _mirror_light(scene: SynthScene, gb: GBuffer, em: dict, prims, resolution: int):
    """The light seen in mirror-coated pixels: (indices into the hits (k,), radiance (k,)).

    Pixels whose reflected ray may reach the light (within its angular radius plus the pixel's
    footprint) are re-sampled with m x m sub-rays on their own sphere, m = 16, 32, 64 or 128 so
    that the sub-rays' reflections are about a quarter of the light's angular radius apart (at
    most 128 per side; rim pixels: 16); a sub-ray counts when its reflection hits the light unoccluded and its primary ray is
    not hidden by another primitive. The pixel gets the mean of ``F L`` over its sub-rays.
    """
    mi = gb.mirror_idx
    p, r = gb.points[mi], gb.refl_dir
    if em["kind"] == "distant":
        to = np.broadcast_to(em["l"], p.shape)
        half = np.full(len(p), em["theta"])
    else:
        w = em["q"] - p
        dist = np.linalg.norm(w, axis=1)
        to = w / dist[:, None]
        half = np.arcsin(np.minimum(1.0, em["a"] / dist))
    ang = np.arccos(np.clip(np.einsum("ij,ij->i", r, to), -1.0, 1.0))
    foot = gb.refl_footprint
    cand = np.flatnonzero(ang < half + foot + 1e-9)
    if len(cand) == 0:
        return cand, np.zeros(0)
    # sub-rays per side: the pixel spans about 2 * footprint of reflected directions
    need = np.where(foot[cand] >= np.pi, _MIRROR_SUB, np.ceil(8.0 * foot[cand] / half[cand]))
    m_of = np.select([need <= 16, need <= 32, need <= 64], [16, 32, 64], 128)
    idx, vals = [], []
    for m in np.unique(m_of):
        c = cand[m_of == m]
        v = _mirror_light_subrays(scene, gb, em, prims, resolution, mi[c], int(m))
        idx.append(mi[c])
        vals.append(v)
    idx, vals = np.concatenate(idx), np.concatenate(vals)
    keep = vals > 0
    return idx[keep], vals[keep]


def _mirror_light_subrays(scene: SynthScene, gb: GBuffer, em: dict, prims, resolution: int, ci, m: int):
    """Mean ``F L`` over m x m sub-rays of the hits ``ci`` (k,) on mirror-coated spheres."""
    offs = ((np.arange(m) + 0.5) / m - 0.5) / scene.supersample
    ou, ov = np.meshgrid(offs, offs)
    u, v = _sample_uv(scene, resolution, gb.index[ci])
    o, d = _rays_through(scene, resolution, (u[:, None] + ou.ravel()).ravel(), (v[:, None] + ov.ravel()).ravel())
    pix = np.repeat(np.arange(len(ci)), m * m)
    own = gb.prim[ci][pix]
    t0 = np.full(len(o), np.inf)
    F0 = np.zeros(len(o))
    fres = np.zeros(len(o), dtype=bool)
    nrm = np.zeros_like(o)
    for k in np.unique(own):
        sel = own == k
        t0[sel] = prims[k].interval(o[sel], d[sel])[0]
        F0[sel] = prims[k].material.mirror
        fres[sel] = prims[k].material.fresnel
    ok = np.flatnonzero(np.isfinite(t0) & (t0 > 0))
    ps = o[ok] + t0[ok, None] * d[ok]
    for k in np.unique(own[ok]):
        sel = own[ok] == k
        nrm[ok[sel]] = prims[k].normal(ps[sel])
    ns = nrm[ok]
    rs = _reflect(-d[ok], ns)
    if em["kind"] == "distant":
        hit = rs @ em["l"] >= math.cos(em["theta"])
        tl = None
    else:
        oc = ps - em["q"]
        b = np.einsum("ij,ij->i", oc, rs)
        c = np.einsum("ij,ij->i", oc, oc) - em["a"] ** 2
        h = b * b - c
        tl = -b - np.sqrt(np.maximum(h, 0.0))
        hit = (h >= 0) & (tl > 0)
    k = np.flatnonzero(hit)
    vis = ~occluded(prims, ps[k] + _EPS * ns[k], rs[k], None if tl is None else tl[k])
    vis &= ~occluded(prims, o[ok[k]], d[ok[k]], t0[ok[k]] * (1.0 - 1e-6))
    cos = np.clip(np.einsum("ij,ij->i", ns[k], -d[ok[k]]), 0.0, 1.0)
    f0 = F0[ok[k]]
    F = np.where(fres[ok[k]], f0 + (1.0 - f0) * (1.0 - cos) ** 5, f0)
    return np.bincount(pix[ok[k]], weights=F * em["L"] * vis, minlength=len(ci)) / (m * m)


def _irradiance(prims, p, n, samples):
    """Yield (l (n, 3), E (n,)) per light sample: unit direction to the light and shadowed irradiance.

    Only the points facing the light cast shadow rays; a point set that mostly faces it is not
    subset (the copies would cost more than the rays they save).
    """
    o_all = p + _EPS * n
    for dvec, q, wgt in samples:
        if dvec is not None:
            l = np.broadcast_to(dvec, p.shape)
            cos = n @ dvec
            w_r2 = None
        else:
            w = q - p
            r2 = np.einsum("ij,ij->i", w, w)
            r = np.sqrt(r2)
            l = w / r[:, None]
            cos = np.einsum("ij,ij->i", n, l)
            w_r2 = r2
        lit = cos > 0
        E = np.zeros(len(p))
        n_lit = int(np.count_nonzero(lit))
        if n_lit:
            sel = slice(None) if n_lit > 0.7 * len(p) else lit
            if dvec is not None:
                vis = ~occluded(prims, o_all[sel], dvec)
                e = cos[sel] * vis
            else:
                vis = ~occluded(prims, o_all[sel], l[sel], r[sel])
                e = cos[sel] / w_r2[sel] * vis
            E[sel] = wgt * np.maximum(e, 0.0)
        yield l, E


def _render(scene, gb, samples, resolution, out=None, emitter=None):
    prims = scene.primitives()
    p, n, v = gb.points, gb.normals, gb.view
    rad = np.zeros((len(p), 3))
    spec_pts = gb.ks > 0
    for l, E in _irradiance(prims, p, n, samples):
        f = gb.kd / np.pi
        rad += f * E[:, None]
        if spec_pts.any():
            m = spec_pts & (E > 0)
            h = normalize(l[m] + v[m])
            nh = np.maximum(np.einsum("ij,ij->i", n[m], h), 0.0)
            sh = gb.shininess[m]
            fs = gb.ks[m] * (sh + 8) / (8 * np.pi) * nh ** sh
            rad[m] += (fs * E[m])[:, None]
    # ground bounce onto the object and spheres
    if scene.ground_albedo > 0 and gb.bounce is not None and gb.bounce.nnz:
        cp = gb.cell_points
        up = np.zeros_like(cp)
        up[:, 2] = 1.0
        Ec = sum(E for _, E in _irradiance(prims, cp, up, samples))
        Eb = gb.bounce @ (gb.cell_albedo / np.pi * Ec)
        rad += gb.kd / np.pi * Eb[:, None]
    # mirror coats: the reflected scene, lit directly (one level), and the light itself
    if len(gb.mirror_idx):
        mi, h = gb.mirror_idx, gb.refl_hit
        if h.any():
            E2 = sum(E for _, E in _irradiance(prims, gb.refl_points, gb.refl_normals, samples))
            rad[mi[h]] += (gb.mirror_F[h] * E2)[:, None] * gb.refl_kd / np.pi
        if emitter is not None:
            idx, val = _mirror_light(scene, gb, emitter, prims, resolution)
            rad[idx] += val[:, None]
    Hs, Ws = gb.shape
    img = np.zeros((Hs * Ws, 3))
    img[gb.index] = rad
    s = scene.supersample
    img = img.reshape(resolution, s, resolution, s, 3).mean(axis=(1, 3))
    if out is not None:
        out[...] = img
        return out
    return img.astype(np.float32)


def render_light(scene: SynthScene, resolution: int, direction=None, position=None, *,
                 intensity: float | None = None, light_radius: float = 0.0, light_samples: int = 9,
                 light_angular_radius_deg: float = LIGHT_ANGULAR_RADIUS_DEG) -> np.ndarray:
    """Render the scene under one light.

    Parameters
    ----------
    scene : SynthScene
    resolution : int
        Image width and height (pixels).
    direction : (3,) float, optional
        A distant light from this direction (world, toward the light) with unit irradiance at
        normal incidence.
    position : (3,) float, optional
        A near light at this world position (m). Exactly one of ``direction`` and ``position``.
    intensity : float, optional
        Near-light intensity ``I`` (irradiance ``I cos / r^2``); default ``|position|^2`` (unit
        irradiance at the scene centre).
    light_radius : float
        Radius (m) of a spherical near light; 0 = point light.
    light_samples : int
        Points sampling a spherical light (rounded up to a square), for soft shadows.
    light_angular_radius_deg : float
        How large the light looks in mirror spheres: the angular radius of a distant light (its
        radiance is ``1 / (pi sin^2)`` of it, so its irradiance stays 1), and, for a point near
        light (``light_radius`` 0), the angle its sphere subtends from the scene centre. Diffuse
        shading is unaffected.

    Returns
    -------
    (resolution, resolution, 3) float32
        Linear radiance.
    """
    gb = gbuffer(scene, int(resolution))
    samples = _light_samples(direction, position, intensity, light_radius, light_samples)
    em = _emitter(direction, position, intensity, light_radius, light_angular_radius_deg)
    return _render(scene, gb, samples, int(resolution), emitter=em)


def render_lights(scene: SynthScene, resolution: int, directions=None, *, positions=None,
                  light_radius: float = 0.0, light_samples: int = 9, progress: bool = False,
                  light_angular_radius_deg: float = LIGHT_ANGULAR_RADIUS_DEG) -> np.ndarray:
    """Render one image per distant light (or per near light with ``positions=``).

    Parameters
    ----------
    scene : SynthScene
    resolution : int
    directions : (n, 3) float, optional
        Distant-light directions (normalised here).
    positions : (n, 3) float, optional
        Near-light positions (m) instead, each with intensity ``|position|^2``.
    light_radius, light_samples, light_angular_radius_deg
        As in :func:`render_light`.
    progress : bool
        Show a tqdm bar.

    Returns
    -------
    (n, resolution, resolution, 3) float32
    """
    if (directions is None) == (positions is None):
        raise ValueError("give exactly one of directions= or positions=")
    arr = np.atleast_2d(np.asarray(directions if positions is None else positions, dtype=np.float64))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError("directions/positions must be (n, 3)")
    gb = gbuffer(scene, int(resolution))
    out = np.empty((len(arr), resolution, resolution, 3), dtype=np.float32)
    it = range(len(arr))
    if progress:
        from tqdm import tqdm
        it = tqdm(it, desc="render", unit="img")
    for i in it:
        d, q = (arr[i], None) if positions is None else (None, arr[i])
        s = _light_samples(d, q, None, light_radius if q is not None else 0, light_samples if q is not None else 1)
        em = _emitter(d, q, None, light_radius, light_angular_radius_deg)
        out[i] = _render(scene, gb, s, int(resolution), emitter=em)
    return out


# ============================================================================ masks and truth
def pixel_labels(scene: SynthScene, resolution: int) -> np.ndarray:
    """(H, W) int8 label of each pixel (its centre sub-sample's majority with supersampling).

    :data:`LABEL_BACKGROUND`, :data:`LABEL_GROUND`, :data:`LABEL_OBJECT` or ``LABEL_SPHERE0 + k``.
    """
    gb = gbuffer(scene, int(resolution))
    s = scene.supersample
    lab = gb.labels.reshape(resolution, s, resolution, s).transpose(0, 2, 1, 3).reshape(resolution, resolution, s * s)
    if s == 1:
        return lab[..., 0].copy()
    vals = np.arange(LABEL_BACKGROUND, LABEL_SPHERE0 + scene.n_spheres)
    counts = (lab[..., None] == vals).sum(axis=2)
    return vals[np.argmax(counts, axis=-1)].astype(np.int8)


def sphere_mask(scene: SynthScene, resolution: int) -> np.ndarray:
    """(H, W) int8: index 0..n-1 of the sphere seen at each pixel, -1 elsewhere."""
    lab = pixel_labels(scene, resolution)
    return np.where(lab >= LABEL_SPHERE0, lab - LABEL_SPHERE0, -1).astype(np.int8)


def sphere_pixel_radii(scene: SynthScene, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Projected sphere centres and apparent radii in pixels.

    Returns
    -------
    centers_px : (n, 2) float64
        (u, v) = (column, row) projection of each 3D centre (OpenCV convention).
    radii_px : (n,) float64
        Pinhole: ``f tan(asin(R / D))``, the silhouette's half-angle in pixels along the focal
        length. Orthographic: ``R`` over the pixel pitch (the outline is then an exact circle).
    """
    uv = scene.project(scene.sphere_centers, resolution)
    R = scene.sphere_radius
    if scene.camera_model == "orthographic":
        return uv, np.full(scene.n_spheres, R / scene.metres_per_pixel(resolution))
    K = scene.K(resolution)
    M = scene.world_from_camera()
    c = (scene.sphere_centers - M[:3, 3]) @ M[:3, :3]  # camera coordinates
    D = np.linalg.norm(c, axis=1)
    return uv, K[0, 0] * R / np.sqrt(D * D - R * R)


def sphere_silhouettes(scene: SynthScene, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel counts of each sphere's whole silhouette, and of its part inside the frame.

    Rays through pixel centres on a grid that extends past the frame as far as needed; each
    sphere is tested alone (no occlusion), so ``pixels / whole`` (``pixels`` from
    :func:`sphere_mask`) is the fraction of a sphere that is seen, and ``in_frame / whole`` how
    much of it the frame edge leaves.

    Returns
    -------
    whole : (n,) int64
    in_frame : (n,) int64
    """
    R = int(resolution)
    uv, rpx = sphere_pixel_radii(scene, R)
    whole = np.zeros(scene.n_spheres, dtype=np.int64)
    inside = np.zeros(scene.n_spheres, dtype=np.int64)
    for k, c in enumerate(scene.sphere_centers):
        if not (np.all(np.abs(uv[k]) < 2.0 ** 53) and rpx[k] < 2.0 ** 53):
            # a sphere so far off (--sphere-xy 1e200,0) that its image lies past the pixel
            # coordinates a float holds exactly (or at inf): counted with no pixel
            continue
        h = int(math.ceil(2.0 * rpx[k])) + 2  # off-axis outlines are stretched ellipses: search 2 radii
        u0, v0 = int(round(uv[k, 0])), int(round(uv[k, 1]))
        vv, uu = np.mgrid[v0 - h:v0 + h + 1, u0 - h:u0 + h + 1]
        o, d = _rays_through(scene, R, uu.ravel(), vv.ravel())
        t0, t1 = Sphere(tuple(c), scene.sphere_radius, Material((0, 0, 0)), 0).interval(o, d)
        hit = (t0 <= t1) & (t1 > 0)
        whole[k] = np.count_nonzero(hit)
        inside[k] = np.count_nonzero(hit & (uu.ravel() >= 0) & (uu.ravel() < R) & (vv.ravel() >= 0) & (vv.ravel() < R))
    return whole, inside


# ============================================================================ light directions
def stratified_directions(n: int, hemisphere: str = "upper", seed: int = 0) -> np.ndarray:
    """Jittered equal-area spiral of ``n`` unit directions over the upper hemisphere or full sphere.

    Band ``k`` of ``n`` equal-area bands in z gets one direction at a jittered z inside the band
    and the golden-angle azimuth plus a random global rotation, so the set is stratified
    and random, and deterministic for a ``seed``.

    Returns
    -------
    (n, 3) float64, unit
    """
    check_hemisphere(hemisphere)
    if n < 1:
        raise ValueError("n must be >= 1")
    rng = np.random.default_rng(seed)
    zlo = 0.0 if hemisphere == "upper" else -1.0
    z = 1.0 - (np.arange(n) + rng.random(n)) / n * (1.0 - zlo)
    phi = rng.random() * 2 * np.pi + np.arange(n) * np.pi * (3.0 - math.sqrt(5.0)) + rng.normal(0, 0.1, n)
    r = np.sqrt(np.maximum(0.0, 1 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


# ============================================================================ oracle
def cluster_lightmap(lightmap, n_dirs: int = 2048, hemisphere: str = "upper", rotation=None):
    """Reduce a light map to ``n_dirs`` distant lights (the oracle's discretisation).

    Texels holding more than ``1 / n_dirs`` of the energy (at most ``n_dirs // 8`` of them: a
    sun) become distant lights of their own at their exact directions. The other texels are
    assigned to the nearest of the remaining spiral directions; each cluster
    ``k`` becomes one distant light at its luminance-weighted mean direction ``m_k`` with
    irradiance ``E_k = sum_i L_i w_i (d_i . m_k)`` per channel: the first moment (vector
    irradiance) of the cluster projected on ``m_k``. This is exact for an unshadowed Lambertian
    point that sees the whole cluster (plain ``sum L w`` would overestimate it by
    ``1 + O(cluster radius^2)``); the error elsewhere is second order in the cluster radius. For
    ``hemisphere='upper'`` texels below the horizon are dropped first (as the relighter does).

    Parameters
    ----------
    lightmap : LightMap or tuple
        An object with ``samples() -> (dirs (M, 3), radiance (M, 3), solid_angle (M,))``, or that tuple.
    n_dirs : int
    hemisphere : {'upper', 'full'}
    rotation : (3, 3) float, optional
        Light-map rotation: radiance from ``d`` arrives from ``R d``.

    Returns
    -------
    directions : (k, 3) float64, unit
    irradiance : (k, 3) float64
        ``E_k`` above; only clusters with non-zero energy are returned (k <= n_dirs). Their sum is
        slightly below the map's ``sum L w`` (by the projection factor).
    dropped : int
        Number of texels with non-zero radiance dropped below the horizon.
    """
    check_hemisphere(hemisphere)
    dirs, rad, sa = as_samples(lightmap)
    if not (np.isfinite(rad).all() and np.isfinite(sa).all()):
        raise InputError("light map has non-finite radiance or solid angles")
    if rotation is not None:
        dirs = dirs @ np.asarray(rotation, dtype=np.float64).T
    keep = in_domain(dirs, hemisphere)
    dropped = int(np.count_nonzero(~keep & np.any(rad != 0, axis=1)))
    dirs, rad, sa = dirs[keep], rad[keep], sa[keep]
    E = rad * sa[:, None]
    lum = np.abs(E) @ np.array([0.2126, 0.7152, 0.0722])
    lum = np.where(lum > 0, lum, np.abs(E).sum(axis=1))
    # the brightest texels (a sun) become lights of their own, at their exact directions
    n_solo = min(n_dirs // 8, len(dirs))
    solo = np.zeros(len(dirs), dtype=bool)
    if n_solo > 0 and lum.sum() > 0:
        top = np.argpartition(-lum, n_solo - 1)[:n_solo]
        solo[top[lum[top] > lum.sum() / n_dirs]] = True
    n_cl = max(1, n_dirs - int(solo.sum()))
    centres = stratified_directions(n_cl, hemisphere, seed=12345)
    rest = ~solo
    _, lab = cKDTree(centres).query(dirs[rest])
    wgt = lum[rest]
    mean = np.stack([np.bincount(lab, weights=wgt * dirs[rest, c], minlength=n_cl) for c in range(3)], axis=1)
    nrm = np.linalg.norm(mean, axis=1, keepdims=True)
    mean = np.where(nrm > 0, mean / np.maximum(nrm, 1e-300), centres)
    if hemisphere == "upper":  # a mean of texels with z >= 0 has z >= 0; guard rounding
        mean[:, 2] = np.maximum(mean[:, 2], 0.0)
        mean = normalize(mean)
    # first moment (vector irradiance) of each channel, projected on the cluster direction
    cosk = np.einsum("ij,ij->i", dirs[rest], mean[lab])
    irr = np.stack([np.bincount(lab, weights=E[rest, c] * cosk, minlength=n_cl) for c in range(3)], axis=1)
    mean = np.concatenate([dirs[solo], mean])
    irr = np.concatenate([E[solo], irr])
    nz = np.any(irr != 0, axis=1)
    return mean[nz], irr[nz], dropped


def render_lightmap(scene: SynthScene, lightmap, resolution: int, n_dirs: int = 2048, hemisphere: str = "upper",
                    rotation=None, progress: bool = False) -> np.ndarray:
    """The oracle: the scene lit directly by a light map (distant illumination).

    ``sum_k E_k * B(d_k)`` over the clusters of :func:`cluster_lightmap`, where ``B(d)`` is the
    distant-light render of :func:`render_light`. Light from below the horizon is dropped for
    ``hemisphere='upper'`` (the relighter's rule). See ``docs/synth.md`` for its measured
    discretisation error.

    Parameters
    ----------
    scene : SynthScene
    lightmap : LightMap or (dirs, radiance, solid_angle)
    resolution : int
    n_dirs : int
        Number of distant lights the map is reduced to.
    hemisphere : {'upper', 'full'}
    rotation : (3, 3) float, optional
    progress : bool

    Returns
    -------
    (resolution, resolution, 3) float32
        Linear radiance.
    """
    d, irr, _ = cluster_lightmap(lightmap, n_dirs, hemisphere, rotation)
    gb = gbuffer(scene, int(resolution))
    acc = np.zeros((resolution, resolution, 3))
    tmp = np.empty_like(acc)
    it = range(len(d))
    if progress:
        from tqdm import tqdm
        it = tqdm(it, desc="oracle", unit="dir")
    for k in it:
        _render(scene, gb, _light_samples(d[k], None, None, 0, 1), int(resolution), out=tmp)
        acc += tmp * irr[k]
    return acc.astype(np.float32)


# ============================================================================ capture writer
def _write_json(path: Path, obj):
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=1) + "\n")


def _capture_encoding(folder: Path, photo: PhotoSettings):
    """``capture.json``'s ``encoding`` for ``photo`` ("auto" = left out); writes ``response.npy`` for gamma 2.2
    and the filmic curve."""
    if not photo.state_encoding:
        return "auto"
    if photo.curve not in ("gamma2.2", "filmic"):
        return photo.curve
    if photo.bits != 8:
        raise ValueError(f"capture.json can state {photo.curve} only for 8-bit files (a 256-entry response); "
                         f"use state_encoding=False for 16-bit {photo.curve}")
    with atomic_output(folder / RESPONSE_FILE) as tmp:
        np.save(tmp, response_table(photo.curve))
    return {"response": RESPONSE_FILE}


def _lens_truth(scene: SynthScene, resolution: int) -> dict:
    ortho = scene.camera_model == "orthographic"
    return {
        "model": scene.camera_model,
        "distance": scene.camera_distance,
        "fov_deg": scene.camera_fov_deg,
        "elevation_deg": scene.camera_elevation_deg,
        "roll_deg": scene.camera_roll_deg,
        "target": list(scene.camera_target),
        "K": None if ortho else scene.K(resolution).tolist(),
        "metres_per_pixel": scene.metres_per_pixel(resolution) if ortho else None,
        "world_from_camera": scene.world_from_camera().tolist(),
    }


def write_synthetic_capture(folder, n_lights: int = 100, resolution: int = 256, light_model: str = "distant",
                            light_distance: float = 2.0, seed: int = 0, ground_albedo: float = 0.3,
                            hemisphere: str = "upper", encoding: str = "linear", noise: float = 0.0,
                            directions=None, progress: bool = True, scene: SynthScene | None = None,
                            light_radius: float = 0.0, light_samples: int = 9, photo: PhotoSettings | None = None,
                            light_angular_radius_deg: float = LIGHT_ANGULAR_RADIUS_DEG,
                            write_lights: bool = True) -> dict:
    """Render a synthetic capture folder: images, ``capture.json``, ``lights.json``, ``truth.json``.

    Parameters
    ----------
    folder : path
        Output folder (created if missing).
    n_lights : int
        Number of images (ignored when ``directions`` is given).
    resolution : int
        Image width and height (pixels).
    light_model : {'distant', 'near'}
        Distant lights of unit irradiance, or point lights at ``light_distance * direction``
        with intensity ``light_distance ** 2`` (unit irradiance at the scene centre).
    light_distance : float
        Distance (m) of near lights from the scene centre.
    seed : int
        Seed of the light directions and of the noise.
    ground_albedo : float
        Albedo of the table (0 = black velvet).
    hemisphere : {'upper', 'full'}
        Where the default directions are drawn; written to ``capture.json``.
    encoding : {'linear', 'srgb8'}
        Shorthand when ``photo`` is None: half-float linear EXR, or 8-bit sRGB PNG (clipped at 1,
        the camera saturating).
    noise : float
        Shorthand when ``photo`` is None: standard deviation of Gaussian noise added to the
        stored values, as a fraction of full scale: to the encoded value before 8-bit
        quantisation (``1/255`` = one code value), or to the linear value for EXR.
    directions : (n, 3) float, optional
        Explicit light directions (normalised here).
    progress : bool
        tqdm progress bar.
    scene : SynthScene, optional
        Scene layout; default ``SynthScene(ground_albedo=ground_albedo)``. When given, its own
        ``ground_albedo`` is used and the ``ground_albedo`` argument is ignored.
    light_radius, light_samples, light_angular_radius_deg
        Spherical near light, and the light's size in mirrors (see :func:`render_light`).
    photo : ffls.synth.photo.PhotoSettings, optional
        The camera: file format, transfer curve, exposure, vignetting, sensor noise, JPEG
        quality, and whether ``capture.json`` states the encoding. Give either ``photo`` or the
        ``encoding``/``noise`` shorthand.
    write_lights : bool
        Write ``lights.json`` (False: an object capture whose lights come from another capture).

    Returns
    -------
    dict
        ``{"folder", "images", "directions" (n, 3), "positions" (n, 3) or None, "scene", "photo"}``.
    """
    check_hemisphere(hemisphere)
    if light_model not in ("distant", "near"):
        raise ValueError("light_model must be 'distant' or 'near'")
    if photo is None:
        if encoding not in ("linear", "srgb8"):
            raise ValueError("encoding must be 'linear' or 'srgb8' (or pass photo=PhotoSettings(...))")
        if noise < 0:
            raise ValueError("noise must be >= 0")
        photo = (PhotoSettings("exr", "linear", noise=noise) if encoding == "linear"
                 else PhotoSettings("png8", "srgb", noise=noise))
        legacy_encoding = encoding
    else:
        if encoding != "linear" or noise != 0.0:
            raise ValueError("give photo= or the encoding=/noise= shorthand, not both")
        legacy_encoding = photo.curve
    folder = Path(folder)
    if scene is None:
        scene = SynthScene(ground_albedo=ground_albedo)
    if directions is None:
        dirs = stratified_directions(int(n_lights), hemisphere, seed)
    else:
        dirs = normalize(np.atleast_2d(np.asarray(directions, dtype=np.float64)))
        if dirs.ndim != 2 or dirs.shape[1] != 3 or not np.all(np.linalg.norm(dirs, axis=1) > 0.5):
            raise ValueError("directions must be (n, 3) non-zero vectors")
    _emitter([0.0, 0.0, 1.0], None, None, 0.0, light_angular_radius_deg)  # checks the angle
    folder.mkdir(parents=True, exist_ok=True)
    cap_encoding = _capture_encoding(folder, photo)
    positions = light_distance * dirs if light_model == "near" else None
    n = len(dirs)
    width = max(4, len(str(n - 1)))
    names = [f"img_{i:0{width}d}.{photo.extension}" for i in range(n)]
    R = int(resolution)
    ortho = scene.camera_model == "orthographic"
    K = None if ortho else scene.K(R)
    gb = gbuffer(scene, R)
    rng = np.random.default_rng([seed, 1])
    it = range(n)
    if progress:
        from tqdm import tqdm
        it = tqdm(it, desc="synth", unit="img")
    for i in it:
        d, q = (dirs[i], None) if positions is None else (None, positions[i])
        s = (_light_samples(d, None, None, 0, 1) if q is None
             else _light_samples(None, q, None, light_radius, light_samples))
        img = _render(scene, gb, s, R, emitter=_emitter(d, q, None, light_radius, light_angular_radius_deg))
        write_photo(folder / names[i], develop(img, photo, rng, K), photo)  # atomic

    centers = scene.sphere_centers
    uv, rpx = sphere_pixel_radii(scene, R)
    mask = sphere_mask(scene, R)
    area_r = [math.sqrt(np.count_nonzero(mask == k) / math.pi) for k in range(scene.n_spheres)]
    whole, in_frame = sphere_silhouettes(scene, R)
    capture = Capture(
        folder=folder, image_names=names, encoding=cap_encoding,
        K=K, dist=np.zeros(5), world_from_camera=scene.world_from_camera(),
        world_from_camera_is_default=False, sphere_radius=scene.sphere_radius if scene.n_spheres else None,
        scene_center=np.zeros(3), hemisphere=hemisphere, image_size=(R, R), units="m",
        extra={"truth": TRUTH_FILE}, camera_model=scene.camera_model,
    )
    spheres = []
    for k in range(scene.n_spheres):
        mat = scene.sphere_material(k)
        spheres.append({
            "material": scene.sphere_materials[k], "center": centers[k].tolist(), "radius": scene.sphere_radius,
            "center_px": uv[k].tolist(), "radius_px": float(rpx[k]), "radius_px_from_area": area_r[k],
            "pixels": int(np.count_nonzero(mask == k)), "silhouette_pixels": int(whole[k]),
            "in_frame_fraction": float(in_frame[k] / max(whole[k], 1)),
            "visible_fraction": float(np.count_nonzero(mask == k) / max(whole[k], 1)),
            "albedo": float(mat.kd[0]),
            "mirror_reflectance": float(mat.mirror), "fresnel": bool(mat.fresnel),
        })
    in_mirror_radius = (light_radius if light_model == "near" and light_radius > 0 else None)
    truth = {
        "format": "ffls-synth-truth",
        "version": 1,
        "light_model": light_model,
        "images": names,
        "directions": dirs.tolist(),
        "positions": None if positions is None else positions.tolist(),
        "intensities": None if positions is None else (light_distance ** 2 * np.ones(n)).tolist(),
        "light_radius": light_radius if light_model == "near" else 0.0,
        "light_angular_radius_deg": light_angular_radius_deg,
        "light_radius_in_mirrors": in_mirror_radius,
        "lights_file": bool(write_lights),
        "sphere_centers": centers.tolist(),
        "sphere_radius": scene.sphere_radius,
        "sphere_centers_px": uv.tolist(),
        "sphere_radii_px": rpx.tolist(),
        "sphere_radii_px_from_area": area_r,
        "spheres": spheres,
        "object": scene.with_object,
        "object_pixels": int(np.count_nonzero(pixel_labels(scene, R) == LABEL_OBJECT)),
        "ground_albedo": scene.ground_albedo,
        "ground_texture": scene.ground_texture,
        "texture_scale": scene.texture_scale,
        "lens": _lens_truth(scene, R),
        "resolution": R,
        "encoding": legacy_encoding,
        "encoding_stated": photo.state_encoding,
        "capture_encoding": None if cap_encoding == "auto" else cap_encoding,
        "file_format": photo.file_format,
        "bits": photo.bits,
        "curve": photo.curve,
        "gamma": photo.gamma,
        "exposure": photo.exposure,
        "vignetting": {"model": photo.vignetting, "coeffs": list(photo.vignetting_coeffs)},
        "sensor_noise": {"shot_gain": photo.shot_gain, "read_noise": photo.read_noise},
        "jpeg_quality": photo.jpeg_quality if photo.file_format == "jpeg" else None,
        "photo": photo.to_json(),
        "noise": photo.noise,
        "seed": seed,
    }
    _write_json(folder / TRUTH_FILE, truth)
    if write_lights:
        save_lights(Lights(image_names=names, directions=dirs, positions=positions), folder / LIGHTS_FILE)
    save_capture(capture)  # last: a folder with capture.json is complete
    return {"folder": folder, "images": names, "directions": dirs, "positions": positions, "scene": scene,
            "photo": photo}


def write_calibration_pair(folder, scene: SynthScene | None = None, n_lights: int = 100, seed: int = 0,
                           hemisphere: str = "upper", directions=None, **kwargs) -> dict:
    """Two captures under the same lights: ``folder/calibration`` (spheres only) and ``folder/object``.

    The calibration capture has the spheres of ``scene`` and no object, and a ``lights.json``
    of the true directions; the object capture has the object and no spheres, and no
    ``lights.json``: its lights are to come from the calibration capture (``--lights
    folder/calibration/lights.json``, matched by order). Both have a ``truth.json``; the object
    capture's noise is drawn with ``seed + 1`` (independent of the calibration's).

    Parameters
    ----------
    folder : path
    scene : SynthScene, optional
        The layout (camera, ground, spheres); default ``SynthScene()``.
    n_lights, seed, hemisphere, directions
        As in :func:`write_synthetic_capture`; the directions are drawn once and shared.
    **kwargs
        Passed to both :func:`write_synthetic_capture` calls (resolution, light_model, photo, ...).

    Returns
    -------
    dict
        ``{"calibration": result, "object": result}`` of :func:`write_synthetic_capture`.
    """
    import dataclasses

    scene = SynthScene() if scene is None else scene
    if scene.n_spheres == 0:
        raise ValueError("a calibration capture needs at least one sphere")
    if directions is None:
        directions = stratified_directions(int(n_lights), hemisphere, seed)
    folder = Path(folder)
    cal = write_synthetic_capture(folder / "calibration", scene=dataclasses.replace(scene, with_object=False),
                                  directions=directions, seed=seed, hemisphere=hemisphere, **kwargs)
    obj = write_synthetic_capture(folder / "object", scene=dataclasses.replace(scene, with_object=True, sphere_xy=(),
                                                                               sphere_materials=()),
                                  directions=directions, seed=seed + 1, hemisphere=hemisphere, write_lights=False,
                                  **kwargs)
    return {"calibration": cal, "object": obj}
