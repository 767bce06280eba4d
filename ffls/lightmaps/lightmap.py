"""Light maps: loading with layout detection and validation, saving, sampling, procedural maps.

A light map gives the radiance arriving at the scene centre from every direction. Layouts
(their geometry lives in :mod:`ffls.lightmaps.sphere_maps`; conventions in ``ffls.conventions``):

``latlong``
    Equirectangular, width = 2 x height (Blender/Cycles / Poly Haven orientation).
``angular``
    Debevec's angular map (light probe): a square holding the whole sphere in its inscribed disc.
``mirrorball``
    A photograph of a mirrored ball: a square holding the whole sphere in its inscribed disc.
``cube``
    Six square faces, in OpenGL face order +X, -X, +Y, -Y, +Z, -Z, stored as (6, R, R, 3). On
    disk a cube map is a *cross* (see :func:`cross_directions`).

Layout detection in :func:`load_lightmap` goes by the aspect ratio: 2:1 is ``latlong``; square
is ``angular`` unless ``layout='mirrorball'`` is given (a square image is ambiguous); 4:3 is a
horizontal cube cross and 3:4 a vertical one. Anything else is rejected.

Validation: NaN or Inf anywhere is an error; negative values (common in real maps after lossy
compression) are clamped to zero with a :class:`LightMapWarning` that gives the count.
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffls import conventions
from ffls.errors import FflsError, InputError, not_a_regular_file
from ffls.io.images import read_image, write_exr, write_hdr

__all__ = [
    "LAYOUTS",
    "MIN_RES",
    "min_size_text",
    "LightMap",
    "LightMapWarning",
    "load_lightmap",
    "gamut_negatives",
    "save_lightmap",
    "detect_layout",
    "MAX_RADIANCE",
    "RGBE_MAX",
    "validate_radiance",
    "cross_directions",
    "cube_to_cross",
    "cross_to_cube",
    "sky_sun_map",
    "paper_map",
    "constant_map",
    "builtin_lightmap",
    "BUILTIN_PROCEDURAL",
    "lightmap_from_spec",
]

#: Light-map layouts.
LAYOUTS = ("latlong", "angular", "mirrorball", "cube")
#: Names of the procedural maps :func:`builtin_lightmap` makes.
BUILTIN_PROCEDURAL = ("sky", "paper")


#: Smallest light map accepted, per layout: the height of a lat-long map (width twice it), the side of an
#: angular or mirror-ball map, the face of a cube map. Smaller maps cannot tell the hemispheres apart
#: (a 2x1 lat-long map has one row straddling the horizon, so its upper-hemisphere integral equals
#: the full sphere's) and resolve no direction.
MIN_RES = {"latlong": 4, "angular": 4, "mirrorball": 4, "cube": 2}
#: Bytes of float64 a band of :meth:`LightMap.downsample` and :meth:`LightMap.sample_bands` holds at a
#: time (16 MiB): their memory does not grow with the map beyond the map itself and its output.
DOWNSAMPLE_BAND_BYTES = 1 << 24


def min_size_text(layout: str) -> str:
    """The smallest accepted size of ``layout`` as ``WxH`` text (for messages)."""
    r = MIN_RES[layout]
    return {"latlong": f"{2 * r}x{r}", "cube": f"{4 * r}x{3 * r} (a cross of {r}x{r} faces)"}.get(layout, f"{r}x{r}")


class LightMapWarning(UserWarning):
    """A light map was loaded but had to be changed (e.g. negative values clamped to zero)."""


def _sphere_map(layout: str):
    from ffls.lightmaps.sphere_maps import get_map

    return get_map(layout)


def _flat_texel_index(m, d: np.ndarray, res: int) -> np.ndarray:
    """Flat index into ``m.shape(res)`` of the texel holding each direction (..., 3)."""
    idx = m.texel_index(d, res)
    if isinstance(idx, tuple):
        idx = np.ravel_multi_index(idx, tuple(m.shape(res)))
    return np.asarray(idx, dtype=np.int64)


@dataclass
class LightMap:
    """Radiance arriving from every direction, in one of :data:`LAYOUTS`.

    Attributes
    ----------
    data : ndarray
        float32 linear radiance, (H, W, 3) for 2-D layouts (``latlong``: W = 2 H; ``angular``,
        ``mirrorball``: W = H) and (6, R, R, 3) for ``cube`` (faces +X, -X, +Y, -Y, +Z, -Z).
        Finite and non-negative.
    layout : str
        One of :data:`LAYOUTS`.
    source : str
        Where it came from: a file path or a procedural map's name.
    clamped_negatives : int
        How many pixels had negative values clamped to 0 when loading.
    colour_note : str or None
        Set when the file was in another colour space and was converted to the working space
        (linear Rec.709, D65) on loading: one line saying from what (:mod:`ffls.io.colourspace`).
    """

    data: np.ndarray
    layout: str
    source: str = ""
    clamped_negatives: int = field(default=0)
    colour_note: str | None = field(default=None, compare=False)

    def __post_init__(self):
        if self.layout not in LAYOUTS:
            raise ValueError(f"layout must be one of {LAYOUTS}, not {self.layout!r}")
        self.data = np.asarray(self.data, dtype=np.float32)
        s = self.data.shape
        if self.layout == "cube":
            ok = len(s) == 4 and s[0] == 6 and s[1] == s[2] and s[3] == 3 and s[1] > 0
        elif self.layout == "latlong":
            ok = len(s) == 3 and s[2] == 3 and s[1] == 2 * s[0] and s[0] > 0
        else:
            ok = len(s) == 3 and s[2] == 3 and s[0] == s[1] and s[0] > 0
        if not ok:
            raise ValueError(f"light-map data of shape {s} does not fit layout {self.layout!r}")

    # ------------------------------------------------------------------ geometry
    @property
    def res(self) -> int:
        """Resolution as :mod:`ffls.lightmaps.sphere_maps` counts it: the height (lat-long), side or face size."""
        return int(self.data.shape[1] if self.layout == "cube" else self.data.shape[0])

    def solid_angles(self) -> np.ndarray:
        """Per-texel solid angle (sr), float64, of shape ``data.shape[:-1]``; 0 outside the valid area."""
        m = _sphere_map(self.layout)
        sa = np.asarray(m.solid_angles(self.res), dtype=np.float64).reshape(self.data.shape[:-1])
        valid = np.asarray(m.valid_mask(self.res), dtype=bool).reshape(self.data.shape[:-1])
        return np.where(valid, sa, 0.0)

    def samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Direction, radiance and solid angle of every valid texel.

        Returns
        -------
        directions : (M, 3) float64
            Unit texel-centre directions in the world frame.
        radiance : (M, 3) float64
            Linear RGB radiance.
        solid_angle : (M,) float64
            Texel solid angles (sr); they sum to 4 pi.
        """
        m = _sphere_map(self.layout)
        res = self.res
        valid = np.asarray(m.valid_mask(res), dtype=bool).ravel()
        d = np.asarray(m.directions(res), dtype=np.float64).reshape(-1, 3)[valid]
        sa = np.asarray(m.solid_angles(res), dtype=np.float64).ravel()[valid]
        rad = self.data.reshape(-1, 3).astype(np.float64)[valid]
        return d, rad, sa

    def sample_bands(self):
        """:meth:`samples` in bands of rows, for sums over a map too large for them at once.

        A lat-long map's bands hold about :data:`DOWNSAMPLE_BAND_BYTES` of
        float64 directions each (the values :meth:`samples` gives, in its order); other layouts
        come as one band.

        Yields
        ------
        directions, radiance, solid_angle
            As :meth:`samples` returns them, for a band of rows.
        """
        if self.layout != "latlong":
            yield self.samples()
            return
        h, w, _ = self.data.shape
        rows = _sphere_map("latlong").row_solid_angles(h)
        band = max(1, DOWNSAMPLE_BAND_BYTES // (w * 3 * 8))
        for i in range(0, h, band):
            d = conventions.latlong_directions(w, h, slice(i, i + band)).reshape(-1, 3)
            rad = self.data[i:i + band].reshape(-1, 3).astype(np.float64)
            yield d, rad, np.repeat(rows[i:i + band], w)

    def total_power(self, hemisphere: str = "full") -> np.ndarray:
        """Integral of radiance over solid angle, sum of ``L dw`` (W m^-2), per channel.

        Parameters
        ----------
        hemisphere : {'full', 'upper'}
            Integrate over the whole sphere or only z >= 0 (what a capture's lights cover: the
            per-light weights of an upper-hemisphere capture sum to this).

        Returns
        -------
        (3,) float64
        """
        total = np.zeros(3)
        for d, rad, sa in self.sample_bands():
            keep = conventions.in_domain(d, hemisphere)
            total += (rad[keep] * sa[keep, None]).sum(axis=0)
        return total

    def irradiance(self, normal=(0.0, 0.0, 1.0)) -> np.ndarray:
        """Cosine-weighted irradiance on a surface facing ``normal``: sum of ``L max(0, n.w) dw``.

        Parameters
        ----------
        normal : (3,) array_like
            Surface normal (normalised here).

        Returns
        -------
        (3,) float64
        """
        n = conventions.normalize(np.asarray(normal, dtype=np.float64))
        total = np.zeros(3)
        for d, rad, sa in self.sample_bands():
            total += (rad * (np.maximum(d @ n, 0.0) * sa)[:, None]).sum(axis=0)
        return total

    def stats(self) -> dict:
        """Summary numbers over the valid texels: ``min``, ``max``, ``mean`` (solid-angle weighted), (3,) each."""
        lo, hi, num, den = np.full(3, np.inf), np.full(3, -np.inf), np.zeros(3), 0.0
        for _, rad, sa in self.sample_bands():
            lo, hi = np.minimum(lo, rad.min(axis=0)), np.maximum(hi, rad.max(axis=0))
            num += (rad * sa[:, None]).sum(axis=0)
            den += sa.sum()
        return {"min": lo, "max": hi, "mean": num / den}

    # ------------------------------------------------------------------ resampling
    def downsample(self, factor: int) -> "LightMap":
        """Area-weighted downsampling of a lat-long map by an integer factor.

        Each output texel is the solid-angle weighted mean of its ``factor x factor`` block, so
        the integral of radiance times solid angle is kept exactly (lat-long texel solid angles
        of a block add up to the solid angle of the merged texel).

        Parameters
        ----------
        factor : int
            Must divide the height.

        Returns
        -------
        LightMap
            Lat-long, (H / factor, W / factor, 3).
        """
        if self.layout != "latlong":
            raise ValueError(f"downsample supports lat-long maps only, not {self.layout!r}")
        factor = int(factor)
        h, w, _ = self.data.shape
        if factor < 1 or h % factor:
            raise ValueError(f"downsample factor {factor} must be >= 1 and divide the height {h}")
        if factor == 1:
            return LightMap(self.data.copy(), self.layout, self.source, self.clamped_negatives)
        # in bands of output rows, float64 only within a band: a 16384 x 8192 map's float64 copies
        # of the whole map (3.2 GB each) made the relight of it with --map-res 512 peak at 10 GB
        rows = _sphere_map("latlong").row_solid_angles(h)  # every texel of a row has its row's
        out = np.empty((h // factor, w // factor, 3), dtype=np.float32)
        band = max(1, DOWNSAMPLE_BAND_BYTES // (factor * w * 3 * 8))  # output rows a band
        for i in range(0, h // factor, band):
            sa = rows[i * factor:(i + band) * factor]
            strip = self.data[i * factor:(i + band) * factor].astype(np.float64) * sa[:, None, None]
            num = strip.reshape(-1, factor, w // factor, factor, 3).sum(axis=(1, 3))
            den = sa.reshape(-1, factor).sum(axis=1) * factor
            out[i:i + num.shape[0]] = num / np.maximum(den, 1e-300)[:, None, None]
        return LightMap(out, "latlong", self.source, self.clamped_negatives)

    def to_latlong(self, height: int) -> "LightMap":
        """Resample to a lat-long map by nearest-texel lookup.

        Parameters
        ----------
        height : int
            Output height; the width is twice that.

        Returns
        -------
        LightMap
            Lat-long, (height, 2 height, 3). Nearest lookup does not keep the integral exactly;
            for lat-long sources whose height is a multiple of ``height`` use :meth:`downsample`.
        """
        height = int(height)
        if self.layout == "latlong" and self.data.shape[0] == height:
            return LightMap(self.data.copy(), "latlong", self.source, self.clamped_negatives)
        d = conventions.latlong_directions(2 * height, height)
        m = _sphere_map(self.layout)
        idx = _flat_texel_index(m, d.reshape(-1, 3), self.res)
        out = self.data.reshape(-1, 3)[idx].reshape(height, 2 * height, 3)
        return LightMap(out, "latlong", self.source, self.clamped_negatives)


# ----------------------------------------------------------------------------- cube crosses
#: Face slots of the crosses: (face name, row, column) in units of faces.
_HCROSS = (("+Z", 0, 1), ("+Y", 1, 0), ("+X", 1, 1), ("-Y", 1, 2), ("-X", 1, 3), ("-Z", 2, 1))
_VCROSS = (("+Z", 0, 1), ("+Y", 1, 0), ("+X", 1, 1), ("-Y", 1, 2), ("-Z", 2, 1), ("-X", 3, 1))
_AX = {"+X": (1, 0, 0), "-X": (-1, 0, 0), "+Y": (0, 1, 0), "-Y": (0, -1, 0), "+Z": (0, 0, 1), "-Z": (0, 0, -1)}
#: (normal, image-right, image-up) of each face as drawn in a cross, seen from inside the cube.
_FACE_FRAMES = {
    "+X": ("+X", "-Y", "+Z"),
    "-X": ("-X", "+Y", "+Z"),
    "+Y": ("+Y", "+X", "+Z"),
    "-Y": ("-Y", "-X", "+Z"),
    "+Z": ("+Z", "-Y", "-X"),
    "-Z": ("-Z", "-Y", "+X"),
}
#: The back face (-X) is drawn upside down at the bottom of a vertical cross.
_VCROSS_FRAMES = dict(_FACE_FRAMES, **{"-X": ("-X", "-Y", "-Z")})


def _cross_slots(orientation: str):
    if orientation == "horizontal":
        return _HCROSS, _FACE_FRAMES, (3, 4)
    if orientation == "vertical":
        return _VCROSS, _VCROSS_FRAMES, (4, 3)
    raise ValueError(f"cross orientation must be 'horizontal' or 'vertical', not {orientation!r}")


def cross_directions(face: int, orientation: str = "horizontal") -> tuple[np.ndarray, np.ndarray]:
    """Texel-centre directions of a cube cross image and which pixels belong to a face.

    The cross is the cube unfolded as seen from inside, centred on +X (the centre of a lat-long
    map), with +Z up. Horizontal (4 x 3 faces)::

                +Z
           +Y   +X   -Y   -X
                -Z

    Vertical (3 x 4 faces): the same without -X in the middle row; -X hangs below -Z, upside
    down::

                +Z
           +Y   +X   -Y
                -Z
                -X

    Side faces are drawn with +Z up; the +Z face has -X at its top, the -Z face +X at its top.

    Parameters
    ----------
    face : int
        Face size R in pixels.
    orientation : {'horizontal', 'vertical'}

    Returns
    -------
    directions : (rows R, cols R, 3) float64
        Unit directions of every pixel centre (zero outside the faces).
    mask : (rows R, cols R) bool
        True on the six face slots.
    """
    slots, frames, (rows, cols) = _cross_slots(orientation)
    R = int(face)
    out = np.zeros((rows * R, cols * R, 3))
    mask = np.zeros((rows * R, cols * R), dtype=bool)
    s = (np.arange(R) + 0.5) / R * 2 - 1  # left to right
    t = 1 - (np.arange(R) + 0.5) / R * 2  # top to bottom
    ss, tt = np.meshgrid(s, t)
    for name, r, c in slots:
        n, right, up = (np.array(_AX[a], dtype=np.float64) for a in frames[name])
        d = n + ss[..., None] * right + tt[..., None] * up
        out[r * R:(r + 1) * R, c * R:(c + 1) * R] = conventions.normalize(d)
        mask[r * R:(r + 1) * R, c * R:(c + 1) * R] = True
    return out, mask


def _cross_index(face: int, orientation: str) -> tuple[np.ndarray, np.ndarray]:
    """(cross flat pixel indices on faces, matching flat cube texel indices)."""
    d, mask = cross_directions(face, orientation)
    cross_idx = np.flatnonzero(mask)
    cube_idx = _flat_texel_index(_sphere_map("cube"), d.reshape(-1, 3)[cross_idx], face)
    if np.unique(cube_idx).size != 6 * face * face:
        raise RuntimeError("cube cross and ffls.lightmaps.sphere_maps cube faces do not match one to one")
    return cross_idx, cube_idx


def cross_to_cube(cross: np.ndarray, orientation: str | None = None) -> np.ndarray:
    """Extract the six faces of a cube cross image.

    Parameters
    ----------
    cross : (3 R, 4 R, C) or (4 R, 3 R, C) ndarray
        Horizontal or vertical cross (see :func:`cross_directions`).
    orientation : {'horizontal', 'vertical'}, optional
        Deduced from the shape when omitted.

    Returns
    -------
    (6, R, R, C) ndarray
        Faces in the order and orientation of ``ffls.lightmaps.sphere_maps.get_map('cube')``.
    """
    h, w = cross.shape[:2]
    if orientation is None:
        orientation = "horizontal" if 3 * w == 4 * h else "vertical" if 4 * w == 3 * h else None
        if orientation is None:
            raise ValueError(f"a cube cross must be 4:3 or 3:4, not {w}x{h}")
    R = w // 4 if orientation == "horizontal" else w // 3
    cross_idx, cube_idx = _cross_index(R, orientation)
    flat = cross.reshape(h * w, -1)
    faces = np.zeros((6 * R * R, flat.shape[1]), dtype=cross.dtype)
    faces[cube_idx] = flat[cross_idx]
    return faces.reshape(6, R, R, -1)


def cube_to_cross(faces: np.ndarray, orientation: str = "horizontal") -> np.ndarray:
    """Lay six cube faces out as a cross image (zero outside the faces).

    Parameters
    ----------
    faces : (6, R, R, C) ndarray
        Faces in ``ffls.lightmaps.sphere_maps`` cube order and orientation.
    orientation : {'horizontal', 'vertical'}

    Returns
    -------
    (3 R, 4 R, C) or (4 R, 3 R, C) ndarray
    """
    R = faces.shape[1]
    _, _, (rows, cols) = _cross_slots(orientation)
    cross_idx, cube_idx = _cross_index(R, orientation)
    out = np.zeros((rows * R * cols * R, faces.shape[-1]), dtype=faces.dtype)
    out[cross_idx] = faces.reshape(6 * R * R, -1)[cube_idx]
    return out.reshape(rows * R, cols * R, -1)


# ----------------------------------------------------------------------------- load / save
def detect_layout(height: int, width: int, layout: str | None = None) -> str:
    """Layout of a 2-D light-map image from its size.

    Parameters
    ----------
    height, width : int
        Image size in pixels.
    layout : str, optional
        An explicit layout; it is checked against the size.

    Returns
    -------
    str
        ``'latlong'`` for 2:1, ``'angular'`` for square (or ``'mirrorball'`` when given),
        ``'cube'`` for a 4:3 or 3:4 cross.

    Raises
    ------
    ValueError
        Size that fits no layout, or does not fit the explicit one.
    """
    if width == 2 * height:
        found = ("latlong",)
    elif width == height:
        found = ("angular", "mirrorball")
    elif (3 * width == 4 * height and width % 4 == 0) or (4 * width == 3 * height and width % 3 == 0):
        found = ("cube",)
    else:
        raise ValueError(
            f"a {width}x{height} image fits no light-map layout (lat-long 2:1, angular/mirror "
            f"ball 1:1, cube cross 4:3 or 3:4)"
        )
    if layout is None:
        return found[0]
    if layout not in LAYOUTS:
        raise ValueError(f"unknown light-map layout {layout!r}; one of {LAYOUTS}")
    if layout not in found:
        raise ValueError(f"a {width}x{height} image cannot be {_a(layout)} map (it looks like {found[0]})")
    return layout


def _a(layout: str) -> str:
    """The layout's name with its article: 'an angular', 'a cube'."""
    return ("an " if layout[0] in "aeiou" else "a ") + layout


#: The largest radiance a light map may hold: the sun is about 1e9 in cd/m^2; a texel near
#: float32's limit (3.4e38) overflows the relighting's 32-bit sums to Inf.
MAX_RADIANCE = 1e30


def validate_radiance(data: np.ndarray, path, out_of_gamut: int = 0) -> tuple[np.ndarray, int]:
    """Reject NaN/Inf and values above :data:`MAX_RADIANCE`, and clamp negatives of light-map data.

    Parameters
    ----------
    data : (..., 3) ndarray
        Radiance.
    path : path-like or str
        Named in the error and the warning.
    out_of_gamut : int, optional
        How many of the negative pixels only the conversion from the file's colour space made
        negative (:func:`gamut_negatives`): the warning says so.

    Returns
    -------
    data : (..., 3) float32
        With negatives set to 0.
    clamped : int
        Number of pixels that had a negative channel.

    Raises
    ------
    InputError
        If any value is NaN, infinite or above :data:`MAX_RADIANCE`.
    """
    data = np.asarray(data, dtype=np.float32)
    bad = np.isfinite(data)
    np.logical_not(bad, out=bad)  # (in place: one mask of the map's size at a time)
    if bad.any():
        npx = int(np.count_nonzero(bad.any(axis=-1)))
        raise InputError(
            f"light map has {npx} pixels with NaN or Inf values "
            f"({int(np.isnan(data).sum())} NaN, {int(np.isinf(data).sum())} Inf channel values)",
            path,
        )
    del bad
    top = float(data.max()) if data.size else 0.0
    if top > MAX_RADIANCE:
        raise InputError(f"light map radiance up to {top:.3g}: beyond {MAX_RADIANCE:.0e}, which no light map holds "
                         "(the renderer's 32-bit sums would overflow); scale it down", path)
    neg = data < 0
    clamped = int(np.count_nonzero(neg.any(axis=-1)))
    if clamped:
        lo = float(data.min())
        data = np.maximum(data, np.float32(0))
        why = ("" if not out_of_gamut else f"; {out_of_gamut} of them are colours outside Rec.709's gamut, made "
               "negative by the conversion from the file's colour space")
        warnings.warn(
            f"{path}: clamped {clamped} pixels with negative values to 0 (most negative {lo:.3g}){why}",
            LightMapWarning,
            stacklevel=3,
        )
    return data, clamped


def gamut_negatives(img) -> int:
    """How many pixels of ``img`` (:class:`ffls.io.images.ImageData`, converted to the working space) have a
    negative channel that the conversion made: non-negative as stored, outside Rec.709's gamut. 0 when the
    file was not converted."""
    if not img.colour_note or img.chromaticities is None:
        return 0
    from ffls.io.colourspace import working_space_conversion

    conv = working_space_conversion(img.chromaticities)
    if conv is None:
        return 0
    neg = np.any(img.pixels < 0, axis=-1)
    if not neg.any():
        return 0
    stored = img.pixels[neg].astype(np.float64) @ np.linalg.inv(conv.matrix).T  # back to the file's values
    return int(np.count_nonzero(np.all(stored >= -1e-6 * np.abs(stored).max(axis=-1, keepdims=True), axis=-1)))


def load_lightmap(path: str | os.PathLike, layout: str | None = None) -> LightMap:
    """Load a light map from an OpenEXR (half or float) or Radiance ``.hdr`` file.

    Parameters
    ----------
    path : path-like
        ``.exr`` or ``.hdr`` file.
    layout : {'latlong', 'angular', 'mirrorball', 'cube'}, optional
        Detected from the aspect ratio when omitted: 2:1 lat-long, square **angular** (a square
        image is ambiguous: pass ``'mirrorball'`` for a mirror-ball photograph), 4:3 / 3:4 a
        cube cross (see :func:`cross_directions`). An explicit layout must fit the size.

    Returns
    -------
    LightMap
        float32, finite, non-negative.

    Raises
    ------
    InputError
        Missing/corrupt file, another format, a size that fits no layout, NaN or Inf values, an EXR
        colour space (``chromaticities``) that cannot be converted to the working space.

    Warns
    -----
    LightMapWarning
        When negative values were clamped to 0 (with the pixel count and file).
    """
    path = Path(path)
    if path.suffix.lower() not in (".exr", ".hdr", ".pic"):
        raise InputError(f"light maps must be .exr or .hdr files, not {path.suffix or '(no extension)'!r}", path)
    img = read_image(path)
    h, w = img.shape
    try:
        layout = detect_layout(h, w, layout)
    except ValueError as e:
        raise InputError(str(e), path) from None
    res = w // 4 if layout == "cube" and 3 * w == 4 * h else (h // 4 if layout == "cube" else h)
    if res < MIN_RES[layout]:
        raise InputError(f"a {w}x{h} light map is too small: {_a(layout)} map must be at least "
                         f"{min_size_text(layout)}", path)
    data, clamped = validate_radiance(img.pixels, path, gamut_negatives(img))
    if layout == "cube":
        data = cross_to_cube(data)
    return LightMap(data, layout, str(path), clamped, colour_note=img.colour_note)


#: The largest value a Radiance RGBE pixel holds (mantissa 255/256 at exponent 127): a larger one
#: is written as 0 by OpenCV, the brightest texel turned black.
RGBE_MAX = 255.0 / 256.0 * 2.0 ** 127


def save_lightmap(lm: LightMap, path: str | os.PathLike, half: bool = False) -> Path:
    """Save a light map as OpenEXR (``.exr``) or Radiance (``.hdr``), chosen by the extension.

    Cube maps are written as a horizontal cross. The write is atomic.

    Parameters
    ----------
    lm : LightMap
    path : path-like
        ``.exr`` or ``.hdr``; any other extension is an error (no other format is substituted).
    half : bool
        EXR only: store half floats.

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    ext = path.suffix.lower()
    img = cube_to_cross(lm.data) if lm.layout == "cube" else lm.data
    if ext == ".exr":
        return write_exr(path, img, half=half)
    if ext in (".hdr", ".pic"):
        if half:
            raise FflsError("half precision applies to .exr output only", path)
        top = float(np.max(img)) if img.size else 0.0
        if top > RGBE_MAX:
            raise FflsError(f"values up to {top:.6g} exceed the Radiance .hdr range ({RGBE_MAX:.3g}): write .exr", path)
        return write_hdr(path, img)
    raise FflsError(f"cannot save a light map as {ext or '(no extension)'!r}; use .exr or .hdr", path)


# ----------------------------------------------------------------------------- procedural maps
def _rgb(x) -> np.ndarray:
    a = np.broadcast_to(np.asarray(x, dtype=np.float64), (3,))
    if not np.all(np.isfinite(a)) or (a < 0).any():
        raise ValueError(f"radiance must be finite and non-negative, got {x!r}")
    return a


def _latlong_solid_angles(height: int) -> np.ndarray:
    return np.asarray(_sphere_map("latlong").solid_angles(height), dtype=np.float64)


def _add_disc(img: np.ndarray, dirs: np.ndarray, sa: np.ndarray, center, radius_deg: float,
              irradiance=None, radiance=None, soft: float = 0.0) -> None:
    """Add a cap of angular radius ``radius_deg`` around ``center`` to ``img`` in place.

    With ``irradiance`` the cap's texels get a radiance that makes the sum of ``L dw`` over the
    cap equal to it exactly (a cap smaller than a texel lands in the nearest texel). ``soft``
    (degrees) adds a smooth fall-off outside the cap (radiance only).
    """
    c = conventions.normalize(np.asarray(center, dtype=np.float64))
    ang = np.degrees(conventions.angle_between(dirs, c))
    inside = ang <= radius_deg
    if not inside.any():
        inside = np.zeros_like(inside)
        inside.flat[np.argmin(ang)] = True
    if irradiance is not None:
        L = _rgb(irradiance) / sa[inside].sum()
        img[inside] += L
    else:
        L = _rgb(radiance)
        w = inside.astype(np.float64)
        if soft > 0:
            w = np.maximum(w, np.exp(-0.5 * ((ang - radius_deg) / soft) ** 2) * (ang > radius_deg))
        img += w[..., None] * L


def sky_sun_map(height: int = 256, sun_direction=(0.5, -0.5, 0.6), sun_irradiance=(30.0, 28.0, 24.0),
                sun_angular_radius_deg: float = 1.0, sky_zenith=(0.15, 0.3, 0.8),
                sky_horizon=(0.7, 0.8, 0.95), ground=(0.08, 0.07, 0.06), sun_radiance=None) -> LightMap:
    """A clear-sky lat-long map: a smooth sky gradient, a small sun disc and a dim ground.

    Parameters
    ----------
    height : int
        Map height (width 2 height).
    sun_direction : (3,) array_like
        Towards the sun (normalised here); world frame, +Z up.
    sun_irradiance : float or (3,) array_like
        The sun's integrated irradiance at normal incidence, sum of ``L dw`` over the disc
        (W m^-2), kept exactly whatever the resolution: a disc smaller than a texel goes into
        the nearest texel.
    sun_angular_radius_deg : float
        Angular radius of the disc (the real sun: 0.27 degrees).
    sky_zenith, sky_horizon : float or (3,) array_like
        Sky radiance at the zenith and at the horizon; in between it follows sqrt(elevation).
    ground : float or (3,) array_like
        Constant radiance below the horizon.
    sun_radiance : float or (3,) array_like, optional
        Give the disc this radiance per texel instead of ``sun_irradiance``.

    Returns
    -------
    LightMap
        Lat-long, deterministic, source ``'sky'``.
    """
    height = int(height)
    dirs = conventions.latlong_directions(2 * height, height)
    z = dirs[..., 2:3]
    zen, hor, gnd = _rgb(sky_zenith), _rgb(sky_horizon), _rgb(ground)
    t = np.sqrt(np.clip(z, 0, 1))
    img = np.where(z >= 0, hor + (zen - hor) * t, gnd)
    sa = _latlong_solid_angles(height)
    if sun_radiance is not None:
        _add_disc(img, dirs, sa, sun_direction, sun_angular_radius_deg, radiance=sun_radiance)
    else:
        _add_disc(img, dirs, sa, sun_direction, sun_angular_radius_deg, irradiance=sun_irradiance)
    return LightMap(img.astype(np.float32), "latlong", "sky")


def paper_map(height: int = 256) -> LightMap:
    """An artificial map in the spirit of the paper's figure: coloured area lights on dark.

    With the default camera (looking along +Y), "front" is -Y (the camera side) and "behind" +Y:
    red from behind, yellow from the front, blue from the left (-X), green from the right (+X),
    each a soft-edged cap of 20 degrees radius 30 degrees above the horizon, on a background of
    0.01.

    Parameters
    ----------
    height : int
        Map height (width 2 height).

    Returns
    -------
    LightMap
        Lat-long, deterministic, source ``'paper'``.
    """
    height = int(height)
    dirs = conventions.latlong_directions(2 * height, height)
    img = np.full(dirs.shape, 0.01)
    sa = _latlong_solid_angles(height)
    el = np.radians(30.0)
    lights = (
        ((0.0, 1.0), (4.0, 0.3, 0.2)),   # red, behind
        ((0.0, -1.0), (4.0, 3.4, 0.8)),  # yellow, front
        ((-1.0, 0.0), (0.3, 0.6, 4.0)),  # blue, left
        ((1.0, 0.0), (0.4, 3.5, 0.6)),   # green, right
    )
    for (x, y), colour in lights:
        c = (np.cos(el) * x, np.cos(el) * y, np.sin(el))
        _add_disc(img, dirs, sa, c, 20.0, radiance=colour, soft=4.0)
    return LightMap(img.astype(np.float32), "latlong", "paper")


def constant_map(height: int = 32, radiance=1.0) -> LightMap:
    """A lat-long map of constant radiance.

    Parameters
    ----------
    height : int
        Map height (width 2 height).
    radiance : float or (3,) array_like
        RGB radiance.

    Returns
    -------
    LightMap
    """
    height = int(height)
    img = np.broadcast_to(_rgb(radiance), (height, 2 * height, 3))
    return LightMap(np.array(img, dtype=np.float32), "latlong", "constant")


def builtin_lightmap(name: str, height: int = 256) -> LightMap:
    """A bundled or procedural light map by name.

    Parameters
    ----------
    name : str
        A bundled map (``ffls.assets.builtin_lightmaps()``: 'courtyard', 'night', 'studio',
        'sunrise') or a procedural one ('sky', 'paper').
    height : int
        Height of procedural maps (bundled ones keep their size).

    Returns
    -------
    LightMap
        The bundled maps carry tiny negative values from lossy compression; they are clamped
        without a warning here (they are known and ours) and counted in ``clamped_negatives``.
    """
    from ffls.assets import builtin_lightmaps

    if name == "sky":
        return sky_sun_map(height)
    if name == "paper":
        return paper_map(height)
    bundled = builtin_lightmaps()
    if name not in bundled:
        raise FflsError(f"unknown light map {name!r}; built-in maps: {', '.join([*bundled, *BUILTIN_PROCEDURAL])}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LightMapWarning)
        return load_lightmap(bundled[name])


def lightmap_from_spec(spec, layout: str | None = None) -> LightMap:
    """A light map from a file path or a built-in name (:func:`builtin_lightmap`).

    An existing file wins (a map black everywhere is an error: it would light nothing); a
    path-like spec (with a suffix or a folder) that does not exist is an error naming it; anything
    else is looked up among the built-in maps, whose error lists them.
    """
    p = Path(spec).expanduser()
    if p.is_file():
        lm = load_lightmap(p, layout=layout)
        if not np.any(lm.data > 0):
            neg = int(lm.clamped_negatives)
            why = (f" ({neg} pixels were negative and clamped to 0, the others are 0: a map of negative values, "
                   "perhaps a difference image?)" if neg else "")
            raise InputError(f"the light map is black everywhere: it lights nothing{why}", p)
        return lm
    if p.suffix or os.sep in str(spec):
        raise InputError(not_a_regular_file(p) or "light map not found", p)
    if layout is not None:
        raise InputError(f"a layout ({layout}) applies to a light-map file, and {spec!r} is a built-in map",
                         "--layout")
    return builtin_lightmap(str(spec))


def as_samples(lightmap_or_samples):
    """Light-map samples as float64 arrays, from a :class:`LightMap` or a ``(dirs, radiance, solid_angle)`` tuple.

    Returns
    -------
    dirs : (M, 3) float64
    radiance : (M, 3) float64
        A single channel is repeated to RGB.
    solid_angle : (M,) float64

    Raises
    ------
    ValueError
        Mismatched lengths, or NaN/Inf anywhere.
    """
    if hasattr(lightmap_or_samples, "samples"):
        dirs, rad, sa = lightmap_or_samples.samples()
    else:
        dirs, rad, sa = lightmap_or_samples
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    rad = np.asarray(rad, dtype=np.float64)
    if rad.ndim == 1:
        rad = rad[:, None]
    rad = rad.reshape(dirs.shape[0], -1)
    if rad.shape[1] == 1:
        rad = np.repeat(rad, 3, axis=1)
    if rad.shape[1] != 3:
        raise ValueError(f"radiance must be (M, 3), not {rad.shape}")
    sa = np.asarray(sa, dtype=np.float64).reshape(-1)
    if sa.shape[0] != dirs.shape[0]:
        raise ValueError("directions, radiance and solid_angle must have the same length")
    if not (np.all(np.isfinite(rad)) and np.all(np.isfinite(sa))):
        raise ValueError("light map radiance or solid angles contain NaN or Inf")
    if not np.all(np.isfinite(dirs)):
        raise ValueError("light map directions contain NaN or Inf (pass valid texels only)")
    return dirs, rad, sa


def sample_bands_of(lightmap_or_samples):
    """:func:`as_samples` of each band of a map's rows (:meth:`LightMap.sample_bands`: a lat-long map
    never holds every texel's samples at once; an 8192 x 4096 map's held 6.3 GB), or of
    ``lightmap_or_samples`` whole where it has no bands (another object, a samples tuple).

    Yields
    ------
    dirs, radiance, solid_angle
        As :func:`as_samples` returns them.
    """
    bands = (lightmap_or_samples.sample_bands() if hasattr(lightmap_or_samples, "sample_bands")
             else [lightmap_or_samples])
    for band in bands:
        yield as_samples(band)
