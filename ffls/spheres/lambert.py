"""Light direction from the shading of one white diffuse sphere.

Masselus, Dutre, Anrys, "The Free-form Light Stage", EGWR 2002, section 5, eq. 2: a Lambertian
sphere of known centre and radius has a known normal ``n`` at every pixel, and its intensity is
``I = rho E max(0, n . l)``; least squares over the lit pixels gives ``l``.

Additions, each needed on real photographs and independent renders:

* an ambient term ``b`` (Hougen & Ahuja 1993, "Estimation of the light source distribution and
  its use in integrated shape recovery from stereo and shading");
* a ground-bounce term ``c g(n)`` with ``g(n) = (1 - n_z) / 2`` (world ``+Z`` up), the form factor
  from a sphere point to an infinite, uniformly lit plane below it. A grey ground lights the
  spheres from below; without this term the fit mistakes that light for a lower light. On the
  lit side ``g`` is linear in ``n`` and so collinear with ``b`` and the ``n_z`` part of ``l``:
  only the shadow side separates them, so shadow-side pixels are fitted too;
* pixels near the terminator (``|n . l| < terminator``) are left out (area-light penumbra and
  the kink of ``max``); the fit is repeated with the new classification until it is stable;
* robust residual rejection (MAD) removes cast shadows, specks and highlights;
* saturated, clipped-black and non-finite pixels are never used (the caller's ``valid`` mask);
  noisy near-zero and negative values are used (censoring them by value biases the fit), and
  where some pixels are clipped at the black floor, those the model predicts near the floor are
  left out too (censoring by the prediction, not by the noisy value);
* the simplest of the models ``plain`` (``a, l``), ``ambient`` (``+ b``) and ``bounce``
  (``+ b + c g``) that the data support is chosen: the richest whose added term is significant
  (t > 3; BIC dropped the bounce when few shadow pixels were in view, see :func:`_select_model`).

For a fixed lit/shadow classification the model ``I = [n . l > 0] n . v + b + c g(n)`` is linear
in ``v = a l``, ``b`` and ``c``; it is solved with :func:`scipy.optimize.lsq_linear` with
``b, c >= 0``. The angular uncertainty comes from the covariance ``s^2 (A^T A)^-1`` of ``v``
projected on the tangent plane of ``l``.

The pixels and their world-frame normals come from :func:`ffls.spheres.samples.sphere_samples`.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from ffls.conventions import UP
from ffls.spheres.ground import hidden_form_factor, memory_key, observed_bounce, seen_bounce
from ffls.spheres.samples import ground_bounce
from ffls.spheres.uncertainty import correlation_inflation

__all__ = [
    "MODELS",
    "FIXED_MODELS",
    "LambertFit",
    "fit_lambert",
    "SIGNAL_SIGNIFICANCE",
    "shading_signal_p",
    "fit_lambert_MasselusDutreAnrys2002",
    "OwnShadow",
    "own_shadow_of",
    "own_shadow_factor",
    "shadowed_ground_bounce",
    "near_ground_bounce",
    "NEAR_BOUNCE_SIDE",
    "NEAR_BOUNCE_SPOT_SIDE",
    "NEAR_BOUNCE_MAX_SIDE",
    "NEAR_BOUNCE_NODES",
    "solve_normal_equations",
    "tangent_uncertainty_deg",
    "flat_field_terms",
]

#: Per-sphere shading models, simplest first (free bounce term).
MODELS = ("plain", "ambient", "bounce")
#: Models with a calibrated bounce (``c = rho_g a max(l_z, 0)``), simplest first.
FIXED_MODELS = ("fixed", "fixed_ambient")


def tangent_uncertainty_deg(v: np.ndarray, cov_v: np.ndarray) -> float:
    """RMS angular error (degrees) of ``v / |v|`` given the covariance (3, 3) of ``v`` (3,).

    The covariance is projected on the tangent plane of the direction; the result is the square
    root of the trace (the expected angle between the estimate and the truth, RMS).
    """
    v = np.asarray(v, dtype=np.float64)
    nv = float(np.linalg.norm(v))
    if not np.isfinite(nv) or nv == 0.0 or not np.all(np.isfinite(cov_v)):
        return float("inf")
    u = v / nv
    P = np.eye(3) - np.outer(u, u)
    tr = float(np.trace(P @ cov_v @ P)) / (nv * nv)
    return float(np.degrees(np.sqrt(max(tr, 0.0))))


@dataclass
class LambertFit:
    """Result of a per-sphere fit.

    Attributes
    ----------
    status : str
        ``'ok'`` or a rejection reason (``'too_dark'``, ``'saturated'``, ``'shadowed'``, ``'fit_failed'``).
    direction : (3,) float64
        Unit world-frame light direction (NaN when the fit failed).
    intensity : float
        ``a = rho E`` (image units).
    ambient, bounce : float
        ``b`` and ``c`` (0 where the model lacks the term).
    model : str
        One of :data:`MODELS`.
    rms : float
        RMS residual over the pixels used, relative to ``intensity``.
    uncertainty_deg : float
        1-sigma RMS angular error (degrees) of ``direction``: the fit's covariance, inflated by
        the residuals' spatial correlation (``inflation``) where the pixels' positions are
        known. Internal (the combination and its tests use it); the reports give 95% cones
        (:mod:`ffls.spheres.uncertainty`).
    statistical_deg : float
        The same without the correlation inflation (independent residuals).
    inflation : float
        Variance inflation factor of the covariance: pixel count over the effective number of
        independent pixels (:func:`ffls.spheres.uncertainty.correlation_inflation`; 1 without
        pixel positions).
    n_lit, n_shadow : int
        Pixels used on the lit and shadow side.
    n_rejected : int
        Pixels rejected as outliers (cast shadow, highlights).
    n_invalid : int
        Pixels excluded by the validity mask (saturated, clipped at the black floor, non-finite).
    n_saturated : int
        Of those, saturated.
    inliers : (m,) bool
        Pixels used in the final fit (lit or shadow side, outside the terminator band).
    non_outliers : (m,) bool
        Valid pixels that the final model does not reject as outliers, on any side of the
        terminator (what a fit with another classification, such as the joint near-light fit,
        may use).
    ground_ratio : float
        ``c / (a l_z)`` of the free-bounce fit (NaN when not available): this photo's estimate of
        the sphere's ground ratio ``rho_g``.
    ground_ratio_sigma : float
        Its standard deviation (relative noise at least ``rel_noise_floor``); large where the
        photo shows no shadow side and ``c`` is confounded with ``b`` and ``l``.
    bounce_ratio : float or None
        The calibrated ratio imposed in this fit (None: free bounce).
    own_shadow : bool
        Whether the bounce's form factor had the sphere's own shadow on the ground taken out
        (:func:`shadowed_ground_bounce`; only where the model has a bounce).
    """

    status: str
    direction: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    intensity: float = 0.0
    ambient: float = 0.0
    bounce: float = 0.0
    model: str = "plain"
    rms: float = float("nan")
    uncertainty_deg: float = float("inf")
    statistical_deg: float = float("inf")
    inflation: float = 1.0
    n_lit: int = 0
    n_shadow: int = 0
    n_rejected: int = 0
    n_invalid: int = 0
    n_saturated: int = 0
    inliers: np.ndarray | None = None
    non_outliers: np.ndarray | None = None
    ground_ratio: float = float("nan")
    ground_ratio_sigma: float = float("inf")
    bounce_ratio: float | None = None
    own_shadow: bool = False

    def as_dict(self) -> dict:
        """JSON-ready summary (without the pixel mask)."""
        def num(x):
            x = float(x)
            return x if np.isfinite(x) else None

        return {
            "status": self.status,
            "direction": [float(x) for x in self.direction] if np.all(np.isfinite(self.direction)) else None,
            "intensity": num(self.intensity), "ambient": num(self.ambient), "bounce": num(self.bounce),
            "model": self.model, "rms": num(self.rms), "sigma_deg": num(self.uncertainty_deg),
            "inflation": num(self.inflation),
            "n_lit": int(self.n_lit), "n_shadow": int(self.n_shadow), "n_rejected": int(self.n_rejected),
            "n_invalid": int(self.n_invalid), "n_saturated": int(self.n_saturated),
            "ground_ratio": num(self.ground_ratio), "ground_ratio_sigma": num(self.ground_ratio_sigma),
            "bounce_ratio": None if self.bounce_ratio is None else num(self.bounce_ratio),
            "own_shadow": bool(self.own_shadow),
        }


#: Grid of the own-shadow table (:func:`own_shadow_factor`): ``n . up`` from -1 to 1, the light's
#: elevation from :data:`OWN_SHADOW_MIN_ELEVATION_DEG` to 90 degrees, and the cosine of the azimuth
#: between the light and the normal from -1 to 1; and the cosine-weighted directions per entry (a side).
_OS_GRID = (49, 30, 25)
_OS_SIDE = 24
#: Lowest light elevation of the table (degrees); lower lights use it (the ground's irradiance,
#: ``l . up``, which scales the bounce, is then small anyway).
OWN_SHADOW_MIN_ELEVATION_DEG = 3.0


@functools.lru_cache(maxsize=1)
def own_shadow_table() -> np.ndarray:
    """(nz, elevation, cos azimuth) table of :func:`own_shadow_factor` (built once per process, ~0.2 s of CPU).

    A unit sphere rests on the plane ``z = -1``. From the point of normal ``n`` (``n_z`` on the
    first axis, azimuth 0), stratified cosine-weighted directions (Malley's method: the share of
    them in a region is its view factor) are cast down to the plane; a hit is in the sphere's
    shadow when the ray from it toward the light (elevation on the second axis, the cosine of
    its azimuth on the third) meets the sphere.
    """
    nz_n, el_n, az_n = _OS_GRID
    k = _OS_SIDE
    u = (np.arange(k) + 0.5) / k
    u1, u2 = (x.ravel() for x in np.meshgrid(u, u))
    r, ph = np.sqrt(u1), 2.0 * np.pi * u2
    local = np.stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(1.0 - u1)], axis=1)  # (k^2, 3)
    el = np.radians(np.linspace(OWN_SHADOW_MIN_ELEVATION_DEG, 90.0, el_n))
    az = np.arccos(np.linspace(-1.0, 1.0, az_n))
    E, A = np.meshgrid(el, az, indexing="ij")
    L = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1).reshape(-1, 3)
    out = np.zeros((nz_n, el_n * az_n))
    for i, z in enumerate(np.linspace(-1.0, 1.0, nz_n)):
        s = np.sqrt(max(0.0, 1.0 - z * z))
        n = np.array([s, 0.0, z])
        t1 = np.array([-z, 0.0, s]) if s > 0 else np.array([1.0, 0.0, 0.0])
        D = local @ np.stack([t1, np.cross(n, t1), n])  # (k^2, 3) world directions
        Dd = D[D[:, 2] < -1e-12]
        X = n + ((-1.0 - z) / Dd[:, 2])[:, None] * Dd  # hits on the plane
        tc = -X @ L.T  # along the light from the hit to the centre
        d2 = np.einsum("ij,ij->i", X, X)[:, None] - tc * tc
        out[i] = np.count_nonzero((tc > 0) & (d2 < 1.0), axis=0) / D.shape[0]
    return out.reshape(nz_n, el_n, az_n)


class OwnShadow:
    """:func:`own_shadow_factor` of fixed normals for any light: what depends on the normals alone
    (their height and horizontal direction) is computed once (a fit evaluates several lights).

    Parameters
    ----------
    normals : (m, 3) float, unit, world frame
    up : (3,) float, unit
        World up (the ground's normal).
    """

    def __init__(self, normals: np.ndarray, up: np.ndarray = UP):
        nt = np.ascontiguousarray(np.asarray(normals, dtype=np.float64).T)  # (3, m): rows, not a last axis of 3
        self.up = np.asarray(up, dtype=np.float64)
        nz = np.clip(self.up @ nt, -1.0, 1.0)
        nh = nt - self.up[:, None] * nz
        norm = np.sqrt(nh[0] * nh[0] + nh[1] * nh[1] + nh[2] * nh[2])
        self.vertical = norm <= 1e-9  # (any azimuth: the table's azimuth 0)
        nh /= np.where(self.vertical, 1.0, norm)
        self.horizontal = nh  # (3, m) unit horizontal directions
        # bilinear lookup in the (n . up, cos azimuth) plane of the table: the n . up cell and
        # weight are the normals' own (the azimuth's depend on the light)
        nz_n = _OS_GRID[0]
        x = (nz + 1.0) * 0.5 * (nz_n - 1)
        i0 = np.minimum(np.floor(x).astype(np.intp), nz_n - 2)
        self.row = i0 * _OS_GRID[2]  # flat index of the cell's first row in an (nz, az) plane
        self.fx = x - i0

    def __call__(self, light: np.ndarray) -> np.ndarray:
        """(m,) view factor of the own shadow under the distant ``light`` (3,), in [0, 1]."""
        light = np.asarray(light, dtype=np.float64)
        m = self.row.shape[0]
        nl = float(np.linalg.norm(light))
        if not np.isfinite(nl) or nl == 0.0:
            return np.zeros(m)
        light = light / nl
        lz = float(light @ self.up)
        if lz <= 0.0:
            return np.zeros(m)
        table = own_shadow_table()
        _, el_n, az_n = table.shape
        lh = light - lz * self.up
        lhn = float(np.linalg.norm(lh))
        c = (lh / lhn) @ self.horizontal if lhn > 1e-9 else np.ones(m)  # a vertical light: any azimuth
        c[self.vertical] = 1.0
        # the light's elevation is one for all pixels: blend its two table slices, then bilinear
        e = (max(float(np.degrees(np.arcsin(min(lz, 1.0)))), OWN_SHADOW_MIN_ELEVATION_DEG)
             - OWN_SHADOW_MIN_ELEVATION_DEG) / (90.0 - OWN_SHADOW_MIN_ELEVATION_DEG) * (el_n - 1)
        j = min(int(e), el_n - 2)
        t = e - j
        plane = ((1.0 - t) * table[:, j] + t * table[:, j + 1]).ravel()
        y = (np.clip(c, -1.0, 1.0) + 1.0) * 0.5 * (az_n - 1)
        j0 = np.minimum(y.astype(np.intp), az_n - 2)  # (y >= 0: truncation is the floor)
        fy = y - j0
        k = self.row + j0
        lo = plane[k]  # the cell's corners: (i0, j0), (i0, j0 + 1), (i0 + 1, j0), (i0 + 1, j0 + 1)
        lo += fy * (plane[k + 1] - lo)
        k += az_n
        hi = plane[k]
        hi += fy * (plane[k + 1] - hi)
        lo += self.fx * (hi - lo)
        return np.clip(lo, 0.0, 1.0, out=lo)


#: :func:`own_shadow_of`'s kept :class:`OwnShadow` objects: ``(id(normals), up) -> (normals, OwnShadow)``.
_OWN_SHADOWS: dict = {}
#: How many :func:`own_shadow_of` keeps (a capture's spheres, and their recentred samples).
OWN_SHADOWS_KEPT = 16


def own_shadow_of(normals: np.ndarray, up: np.ndarray = UP) -> OwnShadow:
    """The :class:`OwnShadow` of a normals array, made once per array and kept (the last
    :data:`OWN_SHADOWS_KEPT`): a capture's fits reuse their samples' normals, and its per-pixel
    geometry depends on them and ``up`` only. The array must not be changed in place after."""
    up = np.asarray(up, dtype=np.float64)
    key = (memory_key(normals), up.tobytes())  # (the kept array pins that memory)
    hit = _OWN_SHADOWS.get(key)
    if hit is not None:
        return hit[1]
    out = OwnShadow(normals, up)
    if len(_OWN_SHADOWS) >= OWN_SHADOWS_KEPT:
        _OWN_SHADOWS.clear()
    _OWN_SHADOWS[key] = (normals, out)
    return out


def own_shadow_factor(normals: np.ndarray, light: np.ndarray, up: np.ndarray = UP) -> np.ndarray:
    """View factor from sphere points to the sphere's own shadow on the ground it rests on.

    The ground bounce of :func:`ffls.spheres.samples.ground_bounce`, ``(1 - n . up) / 2``, is the
    view factor of an infinite, uniformly lit ground. A sphere resting on the ground shades it
    (for a distant light ``l``: the sphere's projection along ``l``, from the contact point away
    from the light), and its points that face that shadow (the lower shadow side; with a light
    behind the sphere, the side the camera sees) receive less bounce. This is the view factor of
    that shadow: the share of the ground's view factor that is dark. It depends on ``n . up``,
    the light's elevation and the azimuth between them only (the sphere's size cancels); it is
    interpolated (trilinear) in a table of cosine-weighted quadrature (:func:`own_shadow_table`).
    Lights below :data:`OWN_SHADOW_MIN_ELEVATION_DEG` use that elevation; lights below the
    horizon give no shadow (and no ground irradiance). :class:`OwnShadow` evaluates it for
    several lights.

    Parameters
    ----------
    normals : (m, 3) float, unit, world frame
    light : (3,) float
        Direction toward the (distant) light.
    up : (3,) float, unit
        World up (the ground's normal).

    Returns
    -------
    (m,) float in [0, 1]
    """
    return OwnShadow(normals, up)(light)


def shadowed_ground_bounce(normals: np.ndarray, light: np.ndarray, up: np.ndarray = UP,
                           g: np.ndarray | None = None, shadow: OwnShadow | None = None) -> np.ndarray:
    """The ground bounce's form factor less the sphere's own shadow: ``g(n) - S(n, l)``.

    Parameters
    ----------
    normals : (m, 3) float, unit, world frame
    light : (3,) float
        Direction toward the (distant) light.
    up : (3,) float, unit
        World up.
    g : (m,) float, optional
        Precomputed :func:`ffls.spheres.samples.ground_bounce` of ``normals``.
    shadow : OwnShadow, optional
        :class:`OwnShadow` of ``normals`` (reused over the lights of a fit).

    Returns
    -------
    (m,) float in [0, 1]
        ``g`` less :func:`own_shadow_factor`.
    """
    g = ground_bounce(normals, up) if g is None else np.asarray(g, dtype=np.float64)
    shadow = OwnShadow(normals, up) if shadow is None else shadow
    return np.clip(g - shadow(light), 0.0, 1.0)


#: Cosine-weighted directions per side of :func:`near_ground_bounce` (``NEAR_BOUNCE_SIDE^2`` per point),
#: at least: a low lamp takes more (:data:`NEAR_BOUNCE_SPOT_SIDE`).
NEAR_BOUNCE_SIDE = 16
#: Directions per side of :func:`near_ground_bounce` per unit ``d / h`` of the lamp (its ground distance
#: from the sphere over its height): the ground's irradiance peaks under the lamp, in a spot about
#: ``h`` wide seen ``d`` away, which the quadrature must resolve (docs/spheres.md, "Near captures";
#: 6 left a lamp at 5 degrees 11% off, aliased).
NEAR_BOUNCE_SPOT_SIDE = 10.0
#: The most directions per side of :func:`near_ground_bounce` (a lamp at the ground's level).
NEAR_BOUNCE_MAX_SIDE = 96
#: Points of a sphere at which :func:`near_ground_bounce` integrates (the rest are interpolated).
NEAR_BOUNCE_NODES = 128


@functools.lru_cache(maxsize=4)
def cosine_directions(side: int) -> np.ndarray:
    """(side^2, 3) stratified cosine-weighted directions about +z (Malley's method)."""
    u = (np.arange(side) + 0.5) / side
    u1, u2 = (x.ravel() for x in np.meshgrid(u, u))
    r, ph = np.sqrt(u1), 2.0 * np.pi * u2
    return np.stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(1.0 - u1)], axis=1)


#: :func:`_near_bounce_geometry`'s kept results, by their inputs (bytes).
NEAR_GEOMETRIES: dict = {}
#: How many :func:`_near_bounce_geometry` keeps (a capture's spheres, and their recentred samples).
NEAR_GEOMETRIES_KEPT = 16


def _near_bounce_geometry(points, normals, center, radius, up, side) -> tuple:
    """What :func:`_near_bounce_quadrature` needs that does not depend on the light: per point and
    quadrature direction, whether the direction meets the ground (``down``), the ground point
    ``X`` and ``W . W`` for ``W = center - X``; made once per sphere and process (every photo's near fit
    integrates at the same nodes), so the same floats as made at every call."""
    key = (points.tobytes(), normals.tobytes(), center.tobytes(), float(radius), up.tobytes(), int(side))
    hit = NEAR_GEOMETRIES.get(key)
    if hit is not None:
        return hit
    G = center - radius * up
    loc = cosine_directions(int(side))
    # a tangent frame per normal
    helper = np.where(np.abs(normals @ up)[:, None] < 0.9, up[None, :], np.roll(up, 1)[None, :])
    t1 = np.cross(normals, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normals, t1)
    D = loc[None, :, 0, None] * t1[:, None, :] + loc[None, :, 1, None] * t2[:, None, :] \
        + loc[None, :, 2, None] * normals[:, None, :]  # (m, s, 3)
    dz = D @ up
    down = dz < -1e-9
    height = points @ up - float(G @ up)
    X = points[:, None, :] + (np.maximum(height, 0.0)[:, None] / np.where(down, -dz, 1.0))[..., None] * D
    W = center - X  # the segment from the ground point to the light meets the sphere: own shadow
    out = (down, X, np.einsum("msi,msi->ms", W, W), loc.shape[0])  # (W itself not kept: one subtraction)
    for a in out[:3]:
        a.flags.writeable = False
    if len(NEAR_GEOMETRIES) >= NEAR_GEOMETRIES_KEPT:
        NEAR_GEOMETRIES.clear()
    NEAR_GEOMETRIES[key] = out
    return out


def _near_bounce_quadrature(points, normals, center, radius, S, up, side) -> np.ndarray:
    """:func:`near_ground_bounce` at every point, by quadrature (the light above the contact point)."""
    G = center - radius * up
    e_ref = float((S - G) @ up) / float(np.linalg.norm(S - G)) ** 3
    down, X, WW, n_dirs = _near_bounce_geometry(points, normals, center, radius, up, side)
    W = center - X
    V = S - X
    r2 = np.einsum("msi,msi->ms", V, V)
    r = np.sqrt(r2)
    E = np.maximum(V @ up, 0.0) / (r2 * r)
    tc = np.einsum("msi,msi->ms", W, V) / r
    dark = (tc > 0.0) & (WW - tc * tc < radius * radius)
    E[~down | dark] = 0.0
    return E.sum(axis=1) / (n_dirs * e_ref)


#: :func:`near_ground_bounce`'s triangulations of its nodes, by the nodes' coordinates (bytes).
_NODE_TRIANGULATIONS: dict = {}


def near_ground_bounce(points: np.ndarray, normals: np.ndarray, center: np.ndarray, radius: float,
                       light_position: np.ndarray, up: np.ndarray = UP, side: int | None = None,
                       nodes: int | None = NEAR_BOUNCE_NODES) -> np.ndarray:
    """The ground bounce's form factor under a near (point) light, relative to the contact point.

    For a distant light the ground is lit uniformly (but for the sphere's own shadow) and the
    form factor is :func:`shadowed_ground_bounce`. A point light at ``S`` lights the ground point
    ``x`` with ``E(x) = max(0, (S - x) . up) / |S - x|^3`` (cosine and inverse square): toward a
    light 2 m away at 20 degrees, the ground 0.3 m nearer the light is lit half as much again,
    and the sphere's side facing the light sees the brighter ground. The own shadow is the
    perspective projection of the sphere from ``S`` (a ground point is dark where its segment to
    ``S`` meets the sphere). The result is
    ``(1/pi) integral over the ground of max(0, n . w) E(x(w)) / E(G) dw`` from each surface
    point, ``G = center - radius up`` the contact point: times ``rho_g`` and the sphere's
    irradiance at the distance of ``G`` it is the single bounce of a uniform Lambertian ground of
    albedo ``rho_g``, as :func:`ffls.spheres.combine.fit_near_light` scales it (``rho_k h_k(S)``).
    It depends on the light's distance over the radius as well as on the directions, so it is
    integrated for each light, by stratified cosine-weighted quadrature (``side^2`` directions per
    point, Malley's method). It tends to :func:`shadowed_ground_bounce` as the light recedes.

    The form factor is smooth over the sphere: with ``nodes``, it is integrated at that many
    points (evenly through the given order) and interpolated linearly at the others, in the
    plane perpendicular to the points' mean normal (the nearest node outside the nodes' hull).

    Parameters
    ----------
    points : (m, 3) float
        World-frame surface points (``center + radius * normals``).
    normals : (m, 3) float, unit
    center : (3,) float
        The sphere's centre; it rests on the ground (the plane ``up . x = up . center - radius``).
    radius : float
    light_position : (3,) float
        World-frame position of the light.
    up : (3,) float, unit
    side : int, optional
        Directions per side of the quadrature. By default :data:`NEAR_BOUNCE_SPOT_SIDE` times the
        lamp's ground distance over its height (the spot of bright ground under a low lamp is seen
        at a small angle), within :data:`NEAR_BOUNCE_SIDE` to :data:`NEAR_BOUNCE_MAX_SIDE`: with 16
        for every lamp, the form factor of a sphere's lower half under a lamp 2 m away at 5 (10)
        degrees was 9% (5%) RMS off an area integral over the ground (1.3% and 2.0% now), and matte
        balls read lamps below 20 degrees 0.29 degrees low (0.15 now; docs/spheres.md).
    nodes : int or None
        Points integrated (None: all); the points must lie on less than a hemisphere when fewer
        than all are integrated (the pixels of a sphere seen by a camera do).

    Returns
    -------
    (m,) float, >= 0 (0 everywhere when the light is not above the contact point)
    """
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    center = np.asarray(center, dtype=np.float64)
    S = np.asarray(light_position, dtype=np.float64)
    up = np.asarray(up, dtype=np.float64)
    m = normals.shape[0]
    hG = float((S - center) @ up) + radius
    if not (np.isfinite(hG) and hG > 0.0) or m == 0:
        return np.zeros(m)
    if side is None:
        across = S - center
        d = float(np.linalg.norm(across - (across @ up) * up))
        side = int(np.clip(np.ceil(NEAR_BOUNCE_SPOT_SIDE * d / hG), NEAR_BOUNCE_SIDE, NEAR_BOUNCE_MAX_SIDE))
    if nodes is None or m <= max(int(nodes), 3) * 2:
        return _near_bounce_quadrature(points, normals, center, radius, S, up, side)
    from scipy.interpolate import LinearNDInterpolator
    from scipy.spatial import cKDTree

    at = np.unique(np.linspace(0, m - 1, int(nodes)).round().astype(int))
    values = _near_bounce_quadrature(points[at], normals[at], center, radius, S, up, side)
    axis = normals.mean(axis=0)
    axis /= np.linalg.norm(axis)
    e1 = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    uv = normals @ np.stack([e1, e2], axis=1)
    # the nodes' triangulation depends on the sphere's pixels only: made once per sphere and
    # process, not for every photo (the same Delaunay, so the same interpolation to the bit)
    nodes_uv = np.ascontiguousarray(uv[at])
    key = nodes_uv.tobytes()
    tri = _NODE_TRIANGULATIONS.get(key)
    if tri is None:
        from scipy.spatial import Delaunay

        if len(_NODE_TRIANGULATIONS) >= 64:
            _NODE_TRIANGULATIONS.clear()
        tri = _NODE_TRIANGULATIONS[key] = Delaunay(nodes_uv)
    out = LinearNDInterpolator(tri, values)(uv)
    outside = ~np.isfinite(out)
    if outside.any():
        out[outside] = values[cKDTree(uv[at]).query(uv[outside])[1]]
    out[at] = values
    return np.maximum(out, 0.0)


def _model_map(model: str, ratio: float) -> np.ndarray:
    """Columns (5, p) mapping a model's parameters onto the full design ``[n [lit], 1, g]``.

    ``plain`` is ``v``; ``ambient`` ``v, b``; ``bounce`` ``v, b, c``. The calibrated models
    ``fixed`` (``v``) and ``fixed_ambient`` (``v, b``) tie the bounce to the light,
    ``c = ratio v_z``: the ground's irradiance is ``a max(l_z, 0)`` and it reflects ``ratio``
    of it onto the sphere (see :func:`fit_lambert`), so the ``v_z`` column becomes
    ``n_z [lit] + ratio g``.
    """
    I5 = np.eye(5)
    if model == "plain":
        return I5[:, :3]
    if model == "ambient":
        return I5[:, :4]
    if model == "bounce":
        return I5
    T = I5[:, :4].copy() if model == "fixed_ambient" else I5[:, :3].copy()
    T[4, 2] = ratio
    return T


def solve_normal_equations(G: np.ndarray, h: np.ndarray, n_free: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Least squares from its normal equations ``G x = h`` with ``x[n_free:] >= 0``.

    The linear shading coefficients of this module and of the joint near-light fit
    (:func:`ffls.spheres.combine.fit_near_light`): the light's ``v`` (or ``a``) is free, the
    ambient and bounce coefficients are non-negative. The active set is enumerated (at most two
    bounded coefficients here).

    Parameters
    ----------
    G : (p, p) float
        ``A^T A``, symmetric positive semi-definite.
    h : (p,) float
        ``A^T y``.
    n_free : int
        The first ``n_free`` coefficients are unbounded, the others ``>= 0``.

    Returns
    -------
    x : (p,) float
    G_inv : (p, p) float
        Inverse of ``G`` on the free set of the solution (zeros elsewhere).
    """
    p = G.shape[0]
    first = 0
    try:  # the unconstrained solution, when feasible, is the optimum (convex problem)
        Ginv = np.linalg.inv(G)
        x = Ginv @ h
        if np.isfinite(x).all():
            if (x[n_free:] >= 0).all():
                return x, Ginv
            first = 1  # the enumeration below would reject the full free set again
    except np.linalg.LinAlgError:
        pass
    bounded = list(range(n_free, p))
    best = None
    for mask in range(first, 1 << len(bounded)):
        fixed = [bounded[k] for k in range(len(bounded)) if mask >> k & 1]
        free = [k for k in range(p) if k not in fixed]
        Gf = G[np.ix_(free, free)]
        try:
            Gi = np.linalg.inv(Gf)
        except np.linalg.LinAlgError:
            Gi = np.linalg.pinv(Gf)
        xf = Gi @ h[free]
        if (xf[n_free:] < 0).any():  # the free set lists the unbounded coefficients first
            continue
        x = np.zeros(p)
        x[free] = xf
        q = float(x @ G @ x - 2.0 * x @ h)  # rss - y'y
        if best is None or q < best[0]:
            Ginv = np.zeros((p, p))
            Ginv[np.ix_(free, free)] = Gi
            best = (q, x, Ginv)
    return best[1], best[2]


class _Fit:
    """One linear fit for a fixed classification: parameters, covariance factor, residuals."""

    __slots__ = ("model", "x", "Ginv", "k", "rss", "v", "b", "c")

    def __init__(self, model, T, G5, h5, yy, k, ratio):
        if model.startswith("fixed"):
            G = T.T @ G5 @ T
            h = T.T @ h5
        else:  # T selects the leading columns
            p = T.shape[1]
            G, h = G5[:p, :p].copy(), h5[:p].copy()
        x, Ginv = solve_normal_equations(G, h)
        if model.startswith("fixed") and x[2] < 0:  # light below the horizon: no ground bounce
            T = _model_map(model, 0.0)
            G, h = T.T @ G5 @ T, T.T @ h5
            x, Ginv = solve_normal_equations(G, h)
            ratio = 0.0
        self.model, self.x, self.Ginv, self.k = model, x, Ginv, k
        self.rss = max(float(yy - 2.0 * x @ h + x @ G @ x), 0.0)
        self.v = x[:3]
        self.b = float(x[3]) if x.size > 3 else 0.0
        if model == "bounce":
            self.c = float(x[4])
        elif model.startswith("fixed"):
            self.c = ratio * max(float(x[2]), 0.0)
        else:
            self.c = 0.0

    @property
    def s2(self) -> float:
        return self.rss / max(self.k - self.x.size, 1)

    def t_last(self) -> float:
        """t statistic of the last coefficient (0 where the data do not determine it)."""
        gi = float(self.Ginv[-1, -1])
        if not (np.isfinite(gi) and gi > 0):  # at its bound, or a numerically singular design
            return 0.0
        var = self.s2 * gi
        return float(self.x[-1] / np.sqrt(var)) if var > 0 else (np.inf if self.x[-1] > 0 else 0.0)


def _select_model(fits: dict, t_min: float = 3.0) -> str:
    """The richest model whose added term is significant (t > ``t_min``), else the next simpler one.

    BIC was tried first: with few shadow-side pixels in view (light from the camera side) it kept
    dropping the bounce term, and the bounce then tilted the light by ~3 degrees. A significant,
    non-negative bounce coefficient is physical, so it is kept.
    """
    for mdl in ("bounce", "ambient", "fixed_ambient"):
        if mdl in fits and fits[mdl].t_last() > t_min:
            return mdl
    for mdl in ("plain", "fixed"):
        if mdl in fits:
            return mdl
    return next(iter(fits))


_TRIU = np.triu_indices(5)
#: Positions in the product table of the shadow-side entries (``1, g`` rows): (3,3), (3,4), (4,4).
_S_IDX = (12, 13, 14)


def _median(x: np.ndarray, overwrite: bool = False) -> float:
    """``np.median`` of a 1-d array (same value), without its overhead; ``overwrite``: partition
    ``x`` in place (its order changes) instead of a copy."""
    n = x.size
    h = n // 2
    kth = h if n % 2 else (h - 1, h)
    if overwrite:
        x.partition(kth)
        p = x
    else:
        p = np.partition(x, kth)
    if n % 2:
        return float(p[h])
    return float(np.mean(p[h - 1:h + 1]))


def _robust_sigma(r: np.ndarray, floor: float) -> float:
    """``max(1.4826 MAD(r), floor)``: the robust standard deviation of residuals ``r`` (m,), at least ``floor``.

    ``r`` is overwritten. The same value as the two medians written out, but the second median is
    only computed where it can exceed the floor: a count of the deviations above the floor's
    equivalent shows when fewer than half of them are (then the MAD is below it, and the floor wins).
    """
    r -= _median(r, overwrite=True)
    np.abs(r, out=r)
    n = r.size
    t = floor / 1.4826 * (1.0 - 1e-9)  # (a margin for the rounding of the comparison in the scaled units)
    if n and int(np.count_nonzero(r > t)) <= n - n // 2 - 1:  # the middle order statistics are <= t
        return float(floor)
    return max(1.4826 * _median(r, overwrite=True), floor)


def _percentile(x: np.ndarray, q: float) -> float:
    """``np.percentile(x, q)`` of a 1-d array (linear interpolation, same value), without its overhead."""
    n = x.size
    pos = q / 100.0 * (n - 1)
    lo = int(np.floor(pos))
    hi = min(lo + 1, n - 1)
    p = np.partition(x, (lo, hi))
    return float(p[lo] + (pos - lo) * (p[hi] - p[lo]))


def _product_table(F, y):
    """Per pixel: the upper triangle of ``f f^T`` (15), ``f y`` (5) and ``y^2`` (1) for ``f = [n, 1, g]``.

    ``F`` is (5, m) (one row per column of the design); the table is (21, m). With it the normal
    equations of any pixel selection are one weighted sum (:func:`_gram`).
    """
    Tb = np.empty((21, F.shape[1]))
    for q, (i, j) in enumerate(zip(*_TRIU)):
        np.multiply(F[i], F[j], out=Tb[q])
    np.multiply(F, y, out=Tb[15:20])
    np.multiply(y, y, out=Tb[20])
    return Tb


def _design_products(normals, g, y):
    """:func:`_product_table` of the design ``[n, 1, g]`` (normals (m, 3), ``g`` and ``y`` (m,))."""
    F = np.empty((5, normals.shape[0]))
    F[:3] = normals.T
    F[3] = 1.0
    F[4] = g
    return _product_table(F, y)


def _gram_from_sums(sl, ss):
    """:func:`_gram`'s result from the lit sums ``sl`` (21,) and the shadow sums ``ss`` (rows 12..20, (9,))."""
    G5 = np.empty((5, 5))
    G5[_TRIU] = sl[:15]
    G5[3, 3] += ss[0]
    G5[3, 4] += ss[1]
    G5[4, 4] += ss[2]
    G5[_TRIU[1], _TRIU[0]] = G5[_TRIU]
    h5 = sl[15:20].copy()
    h5[3:] += ss[6:8]
    return G5, h5, float(sl[20] + ss[8]), int(round(sl[12])), int(round(ss[0]))


def _gram(Tb, lit, shadow):
    """Normal equations of the full design ``[n [lit], 1, g]``: ``A^T A``, ``A^T y``, ``y^T y``, and the counts.

    ``Tb`` is :func:`_product_table`; shadow-side rows only have the last two columns.
    """
    sl = Tb @ lit.astype(np.float64)
    ss = Tb[12:] @ shadow.astype(np.float64)  # rows (3,3), (3,4), (4,4), f y (5), y^2: entries 12..20
    return _gram_from_sums(sl, ss)


class _Gram:
    """:func:`_gram` over the iterations of one fit, updated with the pixels whose class changed.

    Between two iterations only pixels near the terminator and near the rejection threshold change
    class: their products are added or removed (a gather of a few columns of ``Tb``) instead of
    summing every pixel again. Where many changed (the first iterations from a poor start), the
    sums are made afresh (one product of ``Tb`` with both masks).
    """

    #: Above this share of changed pixels the sums are recomputed over all pixels.
    REFRESH = 0.125

    def __init__(self, Tb):
        self.Tb = Tb
        self.lit = self.shadow = None
        self.S = None  # (21, 2): lit sums, shadow sums

    def __call__(self, lit, shadow):
        Tb = self.Tb
        m = Tb.shape[1]
        if self.S is not None:
            dl = np.flatnonzero(lit != self.lit)
            ds = np.flatnonzero(shadow != self.shadow)
        if self.S is None or dl.size + ds.size > self.REFRESH * m:
            W = np.empty((m, 2))
            W[:, 0] = lit
            W[:, 1] = shadow
            self.S = Tb @ W
        else:
            if dl.size:  # +1 where the pixel became lit, -1 where it left
                self.S[:, 0] += Tb[:, dl] @ (2.0 * lit[dl] - 1.0)
            if ds.size:
                self.S[:, 1] += Tb[:, ds] @ (2.0 * shadow[ds] - 1.0)
        self.lit, self.shadow = lit, shadow
        return _gram_from_sums(self.S[:, 0], self.S[12:, 1])


def _fits(models, G5, h5, yy, k, ratio):
    """The candidate fits, computed lazily in :func:`_select_model`'s order (only those it reads)."""
    fits = {}
    for mdl in ("bounce", "ambient", "fixed_ambient"):
        if mdl in models:
            fits[mdl] = _Fit(mdl, _model_map(mdl, ratio), G5, h5, yy, k, ratio)
            if fits[mdl].t_last() > 3.0:
                return fits, mdl
    for mdl in ("plain", "fixed"):
        if mdl in models:
            fits[mdl] = _Fit(mdl, _model_map(mdl, ratio), G5, h5, yy, k, ratio)
            return fits, mdl
    mdl = models[0]
    fits[mdl] = _Fit(mdl, _model_map(mdl, ratio), G5, h5, yy, k, ratio)
    return fits, mdl


def _iterate(normals, y, g, ok, ldir, models, terminator, min_lit, clip_sigma, rel_noise_floor, max_iter, ratio,
             min_shadow=1, floor=None, floor_sigma=2.5, dark_fraction=0.01, Tb=None):
    """Classification / rejection iterations from one start; returns (state, inliers).

    The free bounce ``c`` is only fitted with at least ``min_shadow`` shadow-side pixels: on the
    lit side ``g = (1 - n_z) / 2`` is exactly a combination of the ``1`` and ``n_z`` columns, so
    without shadow pixels the design is singular and its inverse is rounding noise (it gave a
    "significant" bounce with a zero ratio uncertainty that then dominated the capture-wide
    calibration, :func:`ffls.spheres.estimate.calibrate_bounce`).

    ``Tb`` is :func:`_product_table` of ``[n, 1, g]`` and ``y`` (computed here when None).

    Dark pixels are selected by the model, never by their noisy value (selecting on the observed
    value keeps the bright half of the noise and biases the fit; selecting on the prediction does
    not): pixels whose predicted value is below ``dark_fraction`` of ``a`` (the darkest shadow
    side, where the bounce model is least exact) are left out from the second iteration on.
    ``floor`` (m,) bool, optional: pixels clipped at the black floor (outside ``ok``; their ``y``
    is the clipped value). Then the pixels predicted below ``floor_sigma`` robust noise deviations
    (of the residuals of the unclipped pixels predicted below 10 % of ``a``: the noise near the
    floor, which is below the lit side's shot noise)
    are left out, whatever their observed value, and from the second iteration on the clipped
    pixels predicted above that are used with their clipped value (a Tobit-style cut on the
    model: where clipping is unlikely the clipped value is the data; leaving those pixels out
    would select on the noise again).
    """
    has_floor = floor is not None and bool(floor.any())
    usable = (ok | floor) if has_floor else ok
    inl = ok.copy()
    censored = np.zeros_like(ok)
    best = None
    if Tb is None:
        Tb = _design_products(normals, g, y)
    nl = normals @ ldir
    gram = _Gram(Tb)
    for _ in range(max_iter):
        lit = inl & (nl > terminator)
        shadow = inl & (nl < -terminator)
        if best is not None and np.array_equal(lit, best["lit"]) and np.array_equal(shadow, best["shadow"]):
            # the same classes give the same normal equations: this iteration would repeat the last
            # one exactly (same fit, same inliers) and find it stable, so the last one is the fixed point
            break
        G5, h5, yy, n_lit, n_shadow = gram(lit, shadow)
        if n_lit < min_lit:
            break
        use = lit | shadow
        k = n_lit + n_shadow
        mods = [m for m in models if m != "bounce" or n_shadow >= min_shadow] or list(models)
        fits, mdl = _fits(mods, G5, h5, yy, k, ratio)
        fit = fits[mdl]
        a = float(np.linalg.norm(fit.v))
        if not np.isfinite(a) or a == 0:
            break
        new_dir = fit.v / a
        # robust rejection on all valid pixels (predictions with the current model)
        nl = normals @ new_dir
        res = np.maximum(nl, 0.0)  # (in place: y - (a max(nl, 0) + b + c g))
        res *= a
        res += fit.b
        res += fit.c * g
        if has_floor:
            pred = res.copy()
        else:  # pixels predicted in the darkest shadow
            censored = res < max(dark_fraction * a, 0.0)
        np.subtract(y, res, out=res)
        if has_floor:  # the noise near the floor: residuals of the dark unclipped pixels, whatever their class
            dark = ok & (pred < 0.1 * a)
            rd = res[dark] if dark.sum() >= min_lit else res[use]
            floor_noise = 1.4826 * _median(np.abs(rd - _median(rd)))
            censored = pred < max(dark_fraction * a, floor_sigma * floor_noise)
        sigma = _robust_sigma(res[use], rel_noise_floor * a)  # (of the fitted pixels' residuals)
        np.abs(res, out=res)
        new_inl = res <= clip_sigma * sigma
        new_inl &= usable
        new_inl &= ~censored
        best = dict(model=mdl, fit=fit, fits=fits, G5=G5, lit=lit, shadow=shadow, use=use, dir=new_dir, a=a, nl=nl,
                    censored=censored)
        stable = (np.array_equal(new_inl, inl) and float(new_dir @ ldir) > np.cos(np.radians(1e-3)))
        inl = new_inl
        ldir = new_dir
        if stable:
            break
    return best, inl


def fit_lambert(normals: np.ndarray, values: np.ndarray, valid: np.ndarray | None = None, *,
                n_saturated: int = 0, terminator: float = 0.15, models: tuple[str, ...] = MODELS,
                clip_sigma: float = 4.0, rel_noise_floor: float = 0.01, up: np.ndarray = UP,
                min_lit: int = 30, max_reject_fraction: float = 0.25, max_iter: int = 8,
                bounce_ratio: float | None = None, g: np.ndarray | None = None, min_shadow: int = 1,
                start: np.ndarray | None = None, pixels: tuple[np.ndarray, np.ndarray] | None = None,
                own_shadow: bool = True, own_shadow_tol_deg: float = 0.1, ground: tuple | None = None) -> LambertFit:
    """Fit ``I(n) = a max(0, n . l) + b + c g(n)`` to one sphere's pixels.

    Parameters
    ----------
    normals : (m, 3) float
        Unit world-frame normals.
    values : (m,) float
        Linear intensities.
    valid : (m,) bool, optional
        Pixels that may be used (not saturated, not clipped at the black floor); non-finite values are always
        excluded.
    n_saturated : int
        How many of the invalid pixels are saturated (decides the ``'saturated'`` status).
    terminator : float
        Pixels with ``|n . l| < terminator`` are not used.
    models : tuple of str
        Candidate models (subset of :data:`MODELS`); see :func:`_select_model`. Ignored when
        ``bounce_ratio`` is given.
    clip_sigma : float
        Residuals beyond ``clip_sigma`` robust standard deviations are rejected.
    rel_noise_floor : float
        Lower bound of that standard deviation, relative to the peak intensity (model mismatch
        must not be mistaken for outliers); also the noise level assumed for
        :attr:`LambertFit.ground_ratio_sigma`.
    up : (3,) float
        World up, for the ground-bounce term.
    min_lit : int
        Fewer usable lit pixels than this gives ``'too_dark'`` (or ``'saturated'``).
    max_reject_fraction : float
        More rejected lit pixels than this fraction gives ``'shadowed'``.
    max_iter : int
        Classification / rejection iterations.
    bounce_ratio : float, optional
        The sphere's ground ratio ``rho_g`` (calibrated over the capture,
        :func:`ffls.spheres.estimate.calibrate_bounce`): the bounce is then not a free term but
        ``c = rho_g a max(l_z, 0)`` (the ground's irradiance is ``a l_z`` in the sphere's units;
        it reflects ``rho_g`` of it onto the sphere with the form factor ``g``). The candidate
        models are then ``fixed`` (``a, l``) and ``fixed_ambient`` (``+ b``).
    g : (m,) float, optional
        Precomputed :func:`ground_bounce` of ``normals``.
    min_shadow : int
        The free bounce is fitted only with at least this many shadow-side pixels (on the lit
        side its column is a combination of the ambient and ``n_z`` columns: without shadow
        pixels it is not identifiable at all; with a few, its covariance says how poorly).
    start : (3,) float, optional
        A light direction to start the iterations from (e.g. this sphere's fit of the same photo
        in an earlier pass) instead of the least-squares start on the bright pixels; it only
        saves iterations (the classification is iterated to the same fixed point).
    pixels : ((m,) int, (m,) int), optional
        The pixels' rows and columns: the covariance is then inflated by the residuals' spatial
        correlation (:func:`ffls.spheres.uncertainty.correlation_inflation`); without them the
        residuals are taken as independent.
    own_shadow : bool
        The bounce's form factor is ``g`` less the view factor of the sphere's own shadow on the
        ground (:func:`shadowed_ground_bounce`, for the sphere resting on the ground): it depends
        on the light, so it is made for the start direction and made again, and the fit repeated
        from there, while the fitted direction moves more than ``own_shadow_tol_deg`` (at most
        twice). Without it a photo whose light is behind the sphere (its shadow side, facing the
        camera, looks at its shadow) shows a weak bounce, and the capture's ground ratio comes
        out low (docs/spheres.md, "Ground bounce").
    own_shadow_tol_deg : float
        See ``own_shadow`` (the form factor's change over such a move is below the pixels' noise).
    ground : (GroundView, (p,) float), optional
        The sphere's ground as photographed (:mod:`ffls.spheres.ground`: its view and this photo's
        radiance there): with ``own_shadow``, the form factor less the own shadow is then that of
        :func:`ffls.spheres.ground.observed_bounce` (the seen ground's departure from the uniform
        one added), made for each light as the own shadow is; where the view has its sphere's
        albedo (``kappa``), the seen ground's bounce (:func:`ffls.spheres.ground.seen_bounce`)
        is subtracted from ``values`` and the form factor is the hidden ground's
        (:func:`ffls.spheres.ground.hidden_form_factor`).

    Returns
    -------
    LambertFit
    """
    normals = np.asarray(normals, dtype=np.float64)
    y_all = np.asarray(values, dtype=np.float64)
    split = ground is not None and ground[0].kappa is not None
    if split:  # the seen ground's bounce is measured: subtracted (the hidden ground's is fitted)
        y_all = y_all - ground[0].kappa * seen_bounce(ground[0], ground[1], normals)
    m = y_all.shape[0]
    # (a sum is finite iff its terms are; written out: numpy's sum over a length-3 axis is ~40x slower)
    finite = np.isfinite(y_all) & np.isfinite(normals[:, 0] + normals[:, 1] + normals[:, 2])
    ok = finite.copy()
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool)
    n_invalid = int(m - ok.sum())
    base = LambertFit(status="fit_failed", n_invalid=n_invalid, n_saturated=int(n_saturated))
    if bounce_ratio is not None:
        if not (np.isfinite(bounce_ratio) and bounce_ratio >= 0):
            raise ValueError(f"bounce_ratio must be finite and >= 0, got {bounce_ratio!r}")
        models = ("fixed", "fixed_ambient")
        ratio = float(bounce_ratio)
    else:
        ratio = 0.0
        for mdl in models:
            if mdl not in MODELS:
                raise ValueError(f"unknown model {mdl!r}; expected one of {MODELS}")
    # pixels clipped at the black floor (pixel_validity): censor by the prediction too
    floor = finite & ~ok & (y_all <= 0.0)
    if ok.sum() < min_lit:
        base.status = "saturated" if n_saturated >= max(min_lit, 0.5 * (m - ok.sum())) and n_saturated > 0 else "too_dark"
        return base
    y = np.where(ok | floor, y_all, 0.0)
    g = ground_bounce(normals, up) if g is None else np.asarray(g, dtype=np.float64)
    g_plain = g
    # a bounce in the model: its form factor has the sphere's own shadow taken out (needs a light)
    shade = own_shadow and (bounce_ratio is None and "bounce" in models or bounce_ratio is not None and ratio > 0)
    # initial classification: clearly bright pixels are lit
    peak = _percentile(y[ok], 99.0)
    if not peak > 0:
        base.status = "too_dark"
        return base
    bright = ok & (y > 0.3 * peak)
    if bright.sum() < min_lit:
        base.status = "saturated" if n_saturated > bright.sum() else "too_dark"
        return base
    # the per-pixel products of the design, once for the start and every iteration (made here
    # only where the start or the iterations use them: a bounce with the own shadow makes its own)
    Tb = None
    # start from least squares on the bright pixels (I = n . v + b), from the product table
    if start is not None and np.all(np.isfinite(start)) and np.linalg.norm(start) > 0:
        v0 = np.asarray(start, dtype=np.float64)
    else:
        Tb = _design_products(normals, g, y)
        G5, h5 = _gram(Tb, bright, np.zeros_like(bright))[:2]
        try:
            v0 = np.linalg.solve(G5[:4, :4], h5[:4])[:3]
        except np.linalg.LinAlgError:
            v0 = np.full(3, np.nan)
    # (a second start from the brightness-weighted mean normal of the bright pixels was tried: on
    # small back spheres with a thin lit crescent and strong bounce it converged to wrong
    # solutions that the other spheres then confirmed; a rejection is safer than a wrong light)
    best, inl = None, ok
    if np.all(np.isfinite(v0)) and np.linalg.norm(v0) > 0:
        l_g = v0 / np.linalg.norm(v0)
        if shade:
            shadow = own_shadow_of(normals, up)

            def form(light):  # the bounce's form factor under ``light``
                g_l = shadowed_ground_bounce(normals, light, up, g_plain, shadow)
                if ground is None:
                    return g_l
                if split:
                    return hidden_form_factor(ground[0], light, g_l, normals)
                return observed_bounce(ground[0], ground[1], light, g_l, normals)

            g = form(l_g)
            Tb = _design_products(normals, g, y)
        elif Tb is None:
            Tb = _design_products(normals, g, y)
        best, inl = _iterate(normals, y, g, ok, l_g, models, terminator, min_lit,
                             clip_sigma, rel_noise_floor, max_iter, ratio, min_shadow, floor, Tb=Tb)
        cos_tol = np.cos(np.radians(own_shadow_tol_deg))
        for _ in range(2 if shade else 0):  # the shadow of the fitted light, until the light stays
            if best is None or best["fit"].c <= 0.0 or float(best["dir"] @ l_g) >= cos_tol:
                break  # (no bounce in the chosen model: its form factor does not matter)
            g_new = form(best["dir"])
            nb, ni = _iterate(normals, y, g_new, ok, best["dir"], models, terminator, min_lit, clip_sigma,
                              rel_noise_floor, max_iter, ratio, min_shadow, floor, Tb=_design_products(normals, g_new, y))
            if nb is None:  # (keeps the last fit and its form factor)
                break
            l_g, g, best, inl = best["dir"], g_new, nb, ni
    if best is None:
        base.status = "too_dark"
        return base
    fit, ldir, a, lit, shadow, use = best["fit"], best["dir"], best["a"], best["lit"], best["shadow"], best["use"]
    k = fit.k
    try:
        stat = tangent_uncertainty_deg(fit.v, fit.s2 * fit.Ginv[:3, :3])
    except np.linalg.LinAlgError:
        stat = float("inf")
    nl = best["nl"]  # normals @ ldir
    inflation = 1.0
    if pixels is not None and np.isfinite(stat):
        # misfit leaves smooth residuals: fewer independent pixels than pixels
        res = y - (a * np.maximum(nl, 0.0) + fit.b + fit.c * g)
        rows, cols = pixels
        inflation = correlation_inflation(res[use], np.asarray(rows)[use], np.asarray(cols)[use],
                                          max_factor=k / (2.0 * fit.x.size))[0]
    unc = stat * float(np.sqrt(inflation))
    signal_p = shading_signal_p(y[use], fit)
    # the ground ratio c / (a l_z) of the free-bounce fit and its standard deviation at a relative
    # noise of at least rel_noise_floor: small only where the shadow side separates c from b, l
    ratio_est, ratio_sd = float("nan"), float("inf")
    if "bounce" in best["fits"] and ldir[2] > 0:
        fb = best["fits"]["bounce"]
        ab = float(np.linalg.norm(fb.v))
        lz = fb.v[2] / ab if ab > 0 else 0.0
        if lz > 0:
            s = max(np.sqrt(fb.s2), rel_noise_floor * ab)
            ratio_est = fb.c / (ab * lz)
            ratio_sd = float(s * np.sqrt(max(fb.Ginv[4, 4], 0.0)) / (ab * lz))
            if not fb.Ginv[4, 4] > 0.0:  # c at its bound (or singular): not determined by this photo
                ratio_sd = float("inf")
    cand_lit = ok & (nl > terminator) & ~best["censored"]
    n_rej = int((cand_lit & ~inl).sum())
    fitres = LambertFit(
        status="ok", direction=ldir, intensity=a, ambient=fit.b, bounce=fit.c,
        model=best["model"], rms=float(np.sqrt(fit.rss / k)) / a, uncertainty_deg=unc, statistical_deg=stat,
        inflation=inflation,
        n_lit=int(lit.sum()), n_shadow=int(shadow.sum()),
        n_rejected=int((ok & ~inl & ~best["censored"]).sum()), n_invalid=n_invalid, n_saturated=int(n_saturated), inliers=use,
        non_outliers=inl,
        ground_ratio=ratio_est, ground_ratio_sigma=ratio_sd,
        bounce_ratio=None if bounce_ratio is None else float(bounce_ratio), own_shadow=bool(shade and fit.c > 0),
    )
    # a sphere whose expected lit area is largely outlying is in a cast shadow
    if cand_lit.sum() and n_rej > max_reject_fraction * cand_lit.sum():
        fitres.status = "shadowed"
    elif n_saturated > 0.3 * (int(cand_lit.sum()) + n_saturated):
        fitres.status = "saturated"
    elif not np.isfinite(unc):
        fitres.status = "fit_failed"
    elif not (signal_p < SIGNAL_SIGNIFICANCE and fitres.rms < 1.0):
        # noise only (a blank frame, the lens cap on): the shading is not above the noise (its
        # peak below the residuals' deviation, or no better than a constant): no direction
        fitres.status = "too_dark"
    return fitres


#: Significance level of a sphere's shading against the noise (:func:`shading_signal_p`): the
#: level of the photo's other tests (:data:`ffls.spheres.photo.SIGNIFICANCE`).
SIGNAL_SIGNIFICANCE = 1e-3


def shading_signal_p(y: np.ndarray, fit) -> float:
    """p-value of a sphere's fitted shading against no shading at all (a constant).

    The F-test of the fitted model (``fit``: its ``k`` pixels ``y`` and residual sum of squares)
    against a constant on the same pixels. On a blank frame (the lens cap on, noise only) the
    fit still finds a "direction": i-user15's photometric-stereo set, two 8-bit grey balls, had
    both "ok" (relative residual 3.6 and 5.1 times the fitted intensity, 25 and 33 deg
    statistical uncertainty) and the photo rejected as ``spheres_disagree``; :func:`fit_lambert`
    calls a sphere ``too_dark`` where p is not below :data:`SIGNAL_SIGNIFICANCE` or the
    residuals' deviation exceeds the fitted intensity (``rms > 1``: the lit signal at its peak is
    not above the noise). The pixels are taken as independent: the residuals' correlation
    inflation (:func:`ffls.spheres.uncertainty.correlation_inflation`) is a misfit's smoothness,
    not noise (a lit ball whose residuals are smooth, inflation 70: p 0.19 with it, 2e-80
    without; the set's other lit spheres 1e-44 or below, its blank ones 3e-4 to 0.65).

    Parameters
    ----------
    y : (k,) float
        The fitted pixels' values.
    fit : the fit's least-squares solution (``x``, ``rss``)

    Returns
    -------
    float
    """
    # (the F distribution's survival function is SciPy's ``fdtrc``, which ``scipy.stats.f.sf``
    # calls: scipy.stats' import, about 0.25 s of CPU, is otherwise made only by a fitted roll's
    # test (ffls.spheres.estimate.fit_camera_tilt) and an orthographic capture's lens check)
    from scipy.special import fdtrc

    y = np.asarray(y, dtype=np.float64)
    df1 = max(int(fit.x.size) - 1, 1)
    df2 = y.size - fit.x.size
    if y.size < 2 or not df2 > 0:
        return 1.0
    rss0 = float(np.sum((y - y.mean()) ** 2))
    rss1 = float(fit.rss)
    if not rss0 > rss1:
        return 1.0
    if not rss1 > 0:
        return 0.0
    return float(fdtrc(df1, df2, (rss0 - rss1) / df1 / (rss1 / df2)))


#: The paper's per-sphere method, under its name (GUIDE: one paper per function).
fit_lambert_MasselusDutreAnrys2002 = fit_lambert


def flat_field_terms(normals: np.ndarray, values: np.ndarray, fit: LambertFit, offsets: np.ndarray,
                     g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One photo's share of a sphere's flat-field gradient: the normal equations of a fixed
    multiplicative gradient ``1 + offsets @ k`` across the sphere's disk, with this photo's own
    parameters projected out.

    A lens's fall-off (vignetting) multiplies every photo of a capture by the same smooth field;
    across one sphere's disk it is, to first order, ``1 + k . d`` with ``d`` the pixel's offset
    from the disk's centre in radii. In one photo it is confounded with the light (a gradient
    across the disk tilts the fitted direction by about ``|k|`` radians: 3.5 degrees at 7% per
    radius); over many photos and lights it is not. The joint least squares of the per-photo
    parameters and the shared ``k`` is solved by eliminating the per-photo ones (the Schur
    complement): here, the gradient's columns ``m d`` (``m`` the fitted model, since the field
    multiplies all of it) and the residual, both relative to the fitted intensity, are projected
    off the photo's own columns ``[n . l > 0] n`` (direction and intensity), ``1`` (ambient),
    ``g`` (bounce) and ``m (n . l)`` (a near light's inverse-square fall-off across the sphere,
    whose distance is the photo's own: a near light is not taken for a lens's gradient).

    Parameters
    ----------
    normals : (m, 3) float
    values : (m,) float
        The photo's linear values of the sphere's pixels.
    fit : LambertFit
        The sphere's fit in this photo (``status == 'ok'``); its ``inliers`` are used.
    offsets : (m, 2) float
        The pixels' offsets from the disk's centre (columns, rows), in apparent radii.
    g : (m,) float
        The bounce's form factor of the fit (with its own shadow taken out where it was).

    Returns
    -------
    A : (2, 2) float
        ``Kp^T Kp`` of the projected gradient columns ``Kp``.
    b : (2,) float
        ``Kp^T rp`` of the projected relative residual ``rp``.
    """
    use = np.asarray(fit.inliers, dtype=bool)
    n = np.asarray(normals, dtype=np.float64)[use]
    nl = n @ np.asarray(fit.direction, dtype=np.float64)
    a = float(fit.intensity)
    gu = np.asarray(g, dtype=np.float64)[use]
    model = np.maximum(nl, 0.0) + (fit.ambient + fit.bounce * gu) / a
    # the photo's own columns (6), the gradient's (2) and the relative residual, as one product
    Z = np.empty((nl.size, 9))
    Z[:, :3] = n * (nl > 0.0)[:, None]
    Z[:, 3], Z[:, 4], Z[:, 5] = 1.0, gu, model * nl
    Z[:, 6:8] = model[:, None] * np.asarray(offsets, dtype=np.float64)[use]
    Z[:, 8] = np.asarray(values, dtype=np.float64)[use] / a - model
    G = Z.T @ Z
    # the projection off the photo's columns through their Gram matrix: a pseudo-inverse, since
    # the bounce's column is collinear with the others where no shadow side is in view
    w, V = np.linalg.eigh(G[:6, :6])
    keep = w > w[-1] * 1e-12
    P = (V[:, keep] / w[keep]) @ V[:, keep].T
    C = G[:6, 6:9]  # X^T [K, r]
    R = G[6:9, 6:9] - C.T @ P @ C
    return R[:2, :2], R[:2, 2]
