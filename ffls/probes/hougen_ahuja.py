"""Illumination from a diffuse object of known geometry: Hougen and Ahuja's model sources.

Hougen, Ahuja, "Estimation of the light source distribution and its use in integrated shape
recovery from stereo and shading", ICCV 1993 (summarised in
``shared/papers/illumination-estimation-survey.txt``, section 1). The illumination is a set of
distant point sources at *fixed* directions (the model sources: 5, 9, 17, or a geodesic set)
plus an ambient term. Each observed pixel gives one linear equation in their intensities,

    I_i = rho / pi * (A + sum_k E_k max(0, n_i . l_k)),

solved by least squares (unconstrained, "virtual sources" that may be negative) or with the
intensities constrained non-negative (``scipy.optimize.nnls``); the ambient term ``A`` stays
free either way (the paper's justification: the digitiser's offset). Sources at directions that
carry no light come out near 0. Input: the pixels of a diffuse sphere (normals from its
geometry) or of any diffuse object of known geometry: the function takes per-pixel normals.

The recovered map is the sources spread over their Voronoi cells plus the ambient as uniform
radiance (:func:`ffls.probes.sources.sources_to_latlong`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffls.conventions import normalize
from ffls.errors import InputError
from ffls.probes.linear import as_rgb_pixels, broadcast_albedo, lambert_matrix, neighbour_edges, solve_sources
from ffls.probes.sources import HOUGEN_AHUJA_SIZES, cell_energies, model_sources, sources_to_latlong

__all__ = ["SourceFit", "SourceEnsemble", "hougen_ahuja", "estimate_sources_HougenAhuja1993", "check_normals",
           "normal_confidence", "cell_solid_angles", "average_fits", "ground_column", "ground_axis"]


@dataclass(frozen=True)
class SourceFit:
    """Intensities of model sources recovered from an image, and the fit's quality.

    Attributes
    ----------
    directions : (n, 3) float64
        The model sources (world frame, unit).
    intensities : (n, 3) float64
        Irradiance at normal incidence of each source (W m^-2 in the image's radiance units
        times pi / rho); may be negative when unconstrained.
    ambient : (3,) float64
        The free ambient irradiance ``A`` (0 when not fitted).
    rendered : (m, 3) float64
        The input pixels re-rendered from the recovered lighting.
    rms : float
        RMS of ``rendered - radiance`` over pixels and channels.
    relative_rms : float
        ``rms`` over the RMS of the input.
    condition : float
        Condition number of the (column-normalised) linear system.
    method : str
        ``'HougenAhuja1993'``, ``'SatoSatoIkeuchi1999'``...
    hemisphere : str or dict
        Domain of the sources (``'full'``, ``'upper'`` or ``{'axis': [x, y, z]}``): the map gets
        no source light outside it (the ambient term still covers the whole sphere).
    rank : int
        Numerical rank of the system.
    observed : (n,) bool
        Sources that light at least one pixel (the others are 0).
    ground : (3,) float64 or None
        With :func:`hougen_ahuja`'s ``ground``: the power (W m^-2, as an intensity) of the light
        from below the ground plane, uniform radiance over the directions outside ``hemisphere``;
        None without.
    """

    directions: np.ndarray
    intensities: np.ndarray
    ambient: np.ndarray
    rendered: np.ndarray
    rms: float
    relative_rms: float
    condition: float
    method: str
    hemisphere: object = "full"
    rank: int = 0
    observed: np.ndarray | None = None
    ground: np.ndarray | None = None

    def latlong(self, height: int = 64) -> np.ndarray:
        """The recovered lighting as lat-long radiance (height, 2 height, 3) float64 (may be negative)."""
        return sources_to_latlong(self.directions, self.intensities, height, self.hemisphere, self.ambient,
                                  outside=self.ground)

    def irradiance(self, normals) -> np.ndarray:
        """Irradiance (m, 3) float64 of the recovered lighting on unit ``normals`` (m, 3), unshadowed."""
        n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        E = np.maximum(n @ self.directions.T, 0.0) @ self.intensities + self.ambient
        if self.ground is not None:
            E = E + ground_column(n, self.hemisphere["axis"])[:, None] * self.ground
        return E


@dataclass(frozen=True)
class SourceEnsemble(SourceFit):
    """The average of several :class:`SourceFit` of the same pixels (for example over orientations of the
    source set, :func:`ffls.probes.selection.adaptive_hougen_ahuja`).

    ``directions`` and ``intensities`` hold every member's sources, the intensities divided by the
    number of members, so a point-source rendering of them (``rendered``) is the members' mean;
    :meth:`latlong` averages the members' own maps (each source spread over its own set's Voronoi
    cell, not over a cell of the union). ``members`` holds the fits.
    """

    members: tuple = ()

    def latlong(self, height: int = 64) -> np.ndarray:
        """The mean of the members' lat-long maps (height, 2 height, 3) float64."""
        return np.mean([f.latlong(height) for f in self.members], axis=0)


def average_fits(fits, radiance) -> SourceEnsemble:
    """The mean of fits of the same ``radiance`` (m, 3) pixels as a :class:`SourceEnsemble`.

    Parameters
    ----------
    fits : sequence of SourceFit
        Fits of the same pixels, in the same order (their ``rendered`` rows match).
    radiance : (m,) or (m, 3) array_like
        Those pixels (for the ensemble's ``rms``).

    Returns
    -------
    SourceEnsemble
    """
    fits = tuple(fits)
    if not fits:
        raise ValueError("no fits to average")
    k = len(fits)
    b = as_rgb_pixels(radiance, fits[0].rendered.shape[0])
    rendered = np.mean([f.rendered for f in fits], axis=0)
    rms = float(np.sqrt(np.mean((rendered - b) ** 2)))
    ref = float(np.sqrt(np.mean(b ** 2)))
    observed = [f.observed if f.observed is not None else np.ones(f.directions.shape[0], bool) for f in fits]
    grounds = [f.ground for f in fits]
    if any(g is not None for g in grounds) and not all(g is not None for g in grounds):
        raise ValueError("fits with and without a ground term cannot be averaged")
    return SourceEnsemble(directions=np.concatenate([f.directions for f in fits]),
                          intensities=np.concatenate([f.intensities for f in fits]) / k,
                          ambient=np.mean([f.ambient for f in fits], axis=0), rendered=rendered, rms=rms,
                          relative_rms=rms / ref if ref > 0 else np.inf,
                          condition=float(max(f.condition for f in fits)), method=fits[0].method,
                          hemisphere=fits[0].hemisphere, rank=int(max(f.rank for f in fits)),
                          observed=np.concatenate(observed), members=fits,
                          ground=None if grounds[0] is None else np.mean(grounds, axis=0))


def check_normals(normals) -> np.ndarray:
    """Unit normals (m, 3) float64; NaN, Inf or zero vectors are an InputError."""
    n = np.asarray(normals, dtype=np.float64)
    if n.ndim != 2 or n.shape[1] != 3:
        raise ValueError(f"normals must be (m, 3), not {n.shape}")
    if not np.all(np.isfinite(n)):
        raise InputError("normals hold NaN or Inf (pixels off the object?)")
    norm = np.linalg.norm(n, axis=1)
    if np.any(norm < 1e-9):
        raise InputError("normals hold zero vectors")
    return normalize(n)


#: The ``ambient`` settings of :func:`hougen_ahuja`.
AMBIENTS = (True, False, "free", "nonnegative", "auto")


def resolve_ambient(ambient, nonnegative: bool, hemisphere="full"):
    """The ambient setting ``'auto'`` stands for, given the sources' domain (others are returned as given).

    With sources over the **whole sphere** (geodesic sets, adaptive sets) a uniform ambient is
    already a non-negative combination of the sources: each source spread over its Voronoi cell
    with the same radiance sums to a uniform map. A separate ambient column is then redundant,
    and it is not neutral: a non-negative fit uses it to explain the isotropic part of the shading
    with light spread evenly over every direction, also below the horizon and at the zenith, where
    a night sky or a room has little (``docs/probes.md``, *The ambient term*), so ``'auto'`` leaves
    it out (``False``). With sources over a **hemisphere** (the paper's 5, 9 and 17 rings, or a
    dome) the ambient stands for the light from the other half, which no source holds: ``'auto'``
    keeps it, non-negative with ``nonnegative`` (``'nonnegative'``), else free (``True``).

    Parameters
    ----------
    ambient : bool or {'free', 'nonnegative', 'auto'}
    nonnegative : bool
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}
        The sources' domain.

    Returns
    -------
    bool or {'free', 'nonnegative'}
    """
    if ambient not in AMBIENTS or isinstance(ambient, (int, float)) and not isinstance(ambient, bool):
        raise ValueError(f"ambient must be one of {AMBIENTS}, not {ambient!r}")
    if ambient != "auto":
        return ambient
    if isinstance(hemisphere, str) and hemisphere == "full":
        return False
    return "nonnegative" if nonnegative else True


def ground_axis(ground) -> np.ndarray:
    """The unit up vector (3,) float64 of a ``ground`` argument (the ground plane's normal)."""
    up = np.asarray(ground, dtype=np.float64).reshape(-1)
    if up.shape != (3,) or not np.all(np.isfinite(up)) or np.linalg.norm(up) < 1e-12:
        raise ValueError(f"ground must be the plane's normal, a non-zero 3-vector, not {ground!r}")
    return normalize(up)


def ground_column(normals, up) -> np.ndarray:
    """Irradiance (m,) float64 on unit ``normals`` (m, 3) per unit power of uniform radiance below the plane
    of normal ``up``: a power ``P`` over the lower hemisphere is radiance ``P / (2 pi)``, whose irradiance on
    a normal ``n`` is ``pi (P / 2 pi) (1 - n . up) / 2 = P (1 - n . up) / 4`` (all of it facing straight
    down, half of it on a vertical normal, none facing up)."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    return 0.25 * (1.0 - np.clip(n @ ground_axis(up), -1.0, 1.0))


def hougen_ahuja(normals, radiance, albedo=1.0, sources=17, ambient: bool | str = True, nonnegative: bool = False,
                 rcond: float | None = None, axis=(0.0, 0.0, 1.0), hemisphere="full",
                 smoothness: float = 0.0, energy: float = 0.0, ground=None, tv: float = 0.0,
                 power: float = 0.0) -> SourceFit:
    """Recover model-source intensities from a diffuse object's pixels (Hougen and Ahuja 1993).

    Parameters
    ----------
    normals : (m, 3) array_like
        Unit world-frame normals of the observed pixels (a sphere: ``(P - C) / r``).
    radiance : (m,) or (m, 3) array_like
        Linear pixel values (saturated or shadowed pixels already removed by the caller).
    albedo : float, (3,), (m,) or (m, 3) array_like
        Diffuse albedo ``rho`` (pixel = ``rho / pi`` x irradiance). With an uncalibrated
        camera the recovered intensities carry the camera's scale.
    sources : int or (n, 3) array_like
        The model sources: a size for :func:`ffls.probes.sources.model_sources` (5, 9, 17: rings
        on the hemisphere around ``axis``; anything else: a geodesic sphere of about that size),
        or explicit directions (their domain is then ``hemisphere``).
    ambient : bool or {'free', 'nonnegative'}
        Fit the ambient term: ``True``/``'free'`` leaves it unconstrained (the paper; it may come
        out negative, and the map with it), ``'nonnegative'`` constrains it too when
        ``nonnegative`` is set (then every texel of the map is >= 0), ``False`` leaves it out.
        ``'auto'``: out when the sources cover the whole sphere, which already hold any uniform
        light, else ``'nonnegative'`` (with ``nonnegative``) or free (:func:`resolve_ambient`).
    nonnegative : bool
        Constrain the source intensities to be non-negative (NNLS).
    rcond : float, optional
        Unconstrained only: truncate singular values below ``rcond`` x the largest (needed
        for large source sets, whose plain least-squares system is singular).
    axis : (3,) array_like
        Pole of the ring sets (5, 9, 17 sources), whose map then covers that hemisphere only.
    hemisphere : Hemisphere, {'full', 'upper'} or {'axis': [x, y, z]}
        Domain of geodesic or explicit sources.
    smoothness : float
        Optional first-difference penalty between neighbouring sources
        (:func:`ffls.probes.linear.solve_sources`); 0 is the paper's plain fit. It makes large
        source sets well posed and fills the directions behind the object from their neighbours.
    energy : float
        Optional minimum-energy penalty on the map's squared radiance, each source spread over
        its Voronoi cell (:func:`ffls.probes.linear.solve_sources`, :func:`cell_solid_angles`);
        0 is the paper's plain fit. Of the maps a diffuse object cannot tell apart it prefers
        the most evenly spread: NNLS alone returns a vertex of the solution set, which can
        gather light spread over many directions into a few sources at their mean direction
        (``docs/probes.md``, *Regularised Hougen-Ahuja*).
    tv : float
        Optional total-variation (edge-preserving) penalty between neighbouring sources, the L1
        norm of their differences (:func:`ffls.probes.linear.solve_sources`); 0 is the paper's
        plain fit. Like ``smoothness`` it fills and evens out spread light, but it charges a lamp
        by its height, not its squared height, so a small bright lamp keeps its peak where the
        quadratic penalty spreads it over its neighbours (``docs/probes.md``, *An edge-preserving
        prior*).
    ground : (3,) array_like, optional
        The normal (up) of a ground plane. The model sources then lie on or above that plane
        (the hemisphere around it: ``hemisphere`` and ``axis`` are set to it), and the light from
        below it is one more unknown, uniform radiance over the lower hemisphere
        (:func:`ground_column`; non-negative with ``nonnegative``): the ground and what stands on
        it, seen by the downward normals. A ball seen from above cannot tell a lamp a few degrees
        above the horizon from one a few degrees below; with sources on both sides, which side
        NNLS chooses depends on where the sources happen to lie (``docs/probes.md``, *The
        orientation of the source set*). ``ambient='auto'`` then means no ambient (the sources
        and the ground hold any uniform light). None (default): sources over ``hemisphere``.

    Returns
    -------
    SourceFit

    Raises
    ------
    InputError
        Non-finite input, fewer pixels than unknowns, or a singular system (sources that no
        pixel sees, or that the pixels cannot tell apart).
    """
    n = check_normals(normals)
    b = as_rgb_pixels(radiance, n.shape[0])
    rho = broadcast_albedo(albedo, n.shape[0])
    up = None
    if ground is not None:
        up = ground_axis(ground)
        axis = up
        hemisphere = {"axis": [float(v) for v in up]}
        if ambient == "auto":
            ambient = False
    if isinstance(sources, (int, np.integer)):
        dirs = model_sources(int(sources), hemisphere, axis)
        if int(sources) in HOUGEN_AHUJA_SIZES:
            hemisphere = {"axis": [float(v) for v in normalize(np.asarray(axis, dtype=np.float64))]}
    else:
        dirs = normalize(np.asarray(sources, dtype=np.float64).reshape(-1, 3))
        if up is not None and np.any(dirs @ up < -1e-9):
            raise ValueError("with a ground plane the sources must lie on or above it (d . ground >= 0)")
    if n.shape[0] == 0:
        raise InputError("no pixels to fit")
    # the model is linear in the irradiance; fit irradiance = pi I / rho (per-pixel albedo allowed)
    target = np.pi * b / rho
    M = lambert_matrix(n, dirs)
    om = cell_solid_angles(dirs, hemisphere) if energy > 0 else None
    if up is not None:  # the ground's power: one more non-negative unknown, a cell of 2 pi sr
        M = np.concatenate([M, ground_column(n, up)[:, None]], axis=1)
        om = None if om is None else np.append(om, 2.0 * np.pi)
    ambient = resolve_ambient(ambient, nonnegative, hemisphere)
    what = f"{dirs.shape[0]} sources{' + ground' if up is not None else ''}{' + ambient' if ambient else ''}"
    sol = solve_sources(M, target, np.ones(n.shape[0]) if ambient else None, nonnegative, rcond, what=what,
                        smoothness=smoothness, edges=neighbour_edges(dirs) if smoothness > 0 or tv > 0 else None,
                        ambient_nonnegative=ambient == "nonnegative", energy=energy, cell_solid_angles=om, tv=tv,
                        power=power)
    k = dirs.shape[0]
    rendered = sol.predicted * rho / np.pi
    rms = float(np.sqrt(np.mean((rendered - b) ** 2)))
    ref = float(np.sqrt(np.mean(b ** 2)))
    return SourceFit(directions=dirs, intensities=sol.x[:k], ambient=sol.ambient, rendered=rendered, rms=rms,
                     relative_rms=rms / ref if ref > 0 else np.inf, condition=sol.condition,
                     method="HougenAhuja1993", hemisphere=hemisphere, rank=sol.rank, observed=sol.observed[:k],
                     ground=None if up is None else sol.x[k].copy())


#: The colour-hdri style name of :func:`hougen_ahuja`.
estimate_sources_HougenAhuja1993 = hougen_ahuja


def cell_solid_angles(directions, hemisphere="full", height: int = 256) -> np.ndarray:
    """Solid angle (n,) float64 of each source's Voronoi cell (sr) within ``hemisphere``.

    Counted on a lat-long grid of ``height`` rows (256: texels of 0.7 degrees, under a third of
    the finest adaptive spacing, 2.6 degrees); a cell that holds no texel gets the solid angle of
    one equatorial texel, the resolution of the count.
    """
    h = int(height)
    om = cell_energies(directions, np.ones((h, 2 * h, 3)), hemisphere)[:, 0]
    texel = (np.pi / h) * (np.pi / h)
    return np.maximum(om, texel)


def normal_confidence(normals, height: int = 64, chunk: int = 4096) -> np.ndarray:
    """How directly a diffuse object's pixels see each direction of a lat-long map.

    Per texel direction ``w``: ``max_i max(0, n_i . w)`` over the pixels' normals. 1 where some
    pixel faces ``w``; 0 for directions that light no pixel (behind a ball seen from one side:
    exactly the camera's antipode); small values mark directions seen only at grazing angles,
    whose light the data barely constrain. Use it as the map's mask/alpha (for example
    ``> 0.2``) and report the rest as unseen.

    Parameters
    ----------
    normals : (m, 3) array_like
    height : int

    Returns
    -------
    (height, 2 height) float64
    """
    from ffls.conventions import latlong_directions

    n = check_normals(normals)
    w = latlong_directions(2 * int(height), int(height)).reshape(-1, 3)
    best = np.zeros(w.shape[0])
    for s in range(0, n.shape[0], chunk):
        best = np.maximum(best, (n[s:s + chunk] @ w.T).max(axis=0))
    return np.clip(best, 0.0, 1.0).reshape(int(height), 2 * int(height))
