"""Colour spaces of files: convert RGB with given chromaticities to the working space.

The working space of ffls (GUIDE section 1) is linear Rec.709 primaries with a D65 white (the
primaries of sRGB, without its transfer function). An OpenEXR file may say that its RGB is in
another space through the standard ``chromaticities`` attribute (red, green, blue and white
CIE 1931 xy; e.g. ACEScg, Rec.2020, a camera's native space). Such pixels are converted on the
way in with a 3x3 matrix that colour-science builds from the primaries and whites
(:func:`colour.matrix_RGB_to_RGB`, with Bradford chromatic adaptation when the whites differ),
and the conversion is reported; a space that cannot be converted is an error, never read as
Rec.709.

This lives in :mod:`ffls.io` (not :mod:`ffls.radiance`) because both photographs
(:mod:`ffls.radiance.photos`) and light maps (:mod:`ffls.lightmaps.lightmap`) are read through
:func:`ffls.io.images.read_image`, and neither package may import the other (same rank): one
conversion, applied where the file is decoded, serves both.

References: S. Westland, C. Ripamonti, V. Cheung, *Computational Colour Science using MATLAB*
(2nd ed., 2012), section 5 (RGB to XYZ from primaries); K. M. Lam, "Metamerism and colour
constancy", PhD thesis, University of Bradford, 1985 (the Bradford transform); OpenEXR
``chromaticities`` attribute (ImfStandardAttributes.h). The arithmetic is colour-science's.
"""
from __future__ import annotations

import warnings

import numpy as np

from ffls.errors import InputError

__all__ = [
    "WORKING_SPACE",
    "CHROMATICITY_TOLERANCE",
    "ColourConversion",
    "working_space_conversion",
    "convert_to_working_space",
]

#: Name of the working space in messages.
WORKING_SPACE = "linear Rec.709 (D65)"
#: Largest |xy| difference at which two sets of chromaticities are the same space (EXR stores
#: them as float32: Rec.709's 0.64 reads back as 0.63999998569...).
CHROMATICITY_TOLERANCE = 1e-5
#: Largest condition number accepted for the RGB -> XYZ matrix of a file's primaries.
_MAX_CONDITION = 1e6


class ColourConversion:
    """The conversion of one file's RGB space to the working space.

    Attributes
    ----------
    matrix : (3, 3) float64 ndarray
        ``working_rgb = matrix @ file_rgb``.
    name : str
        The colour-science name of the file's space when its chromaticities match one (e.g.
        ``'ACEScg'``), else ``'custom'``.
    chromaticities : (8,) float64 ndarray
        As read: red x y, green x y, blue x y, white x y.
    adaptation : str or None
        ``'Bradford'`` when the file's white differs from D65, else None.
    """

    def __init__(self, matrix, name: str, chromaticities, adaptation):
        self.matrix = np.asarray(matrix, dtype=np.float64)
        self.name = name
        self.chromaticities = np.asarray(chromaticities, dtype=np.float64)
        self.adaptation = adaptation

    def describe(self) -> str:
        """One line, e.g. ``"ACEScg (primaries R 0.713,0.293 ...) converted to linear Rec.709 (D65), Bradford"``."""
        c = self.chromaticities
        prim = (f"R {c[0]:.4g},{c[1]:.4g} G {c[2]:.4g},{c[3]:.4g} B {c[4]:.4g},{c[5]:.4g} "
                f"white {c[6]:.4g},{c[7]:.4g}")
        how = f", {self.adaptation} chromatic adaptation" if self.adaptation else ""
        return f"colour space {self.name} ({prim}) converted to {WORKING_SPACE}{how}"

    def apply(self, rgb) -> np.ndarray:
        """``rgb`` (..., 3) converted, float32."""
        x = np.asarray(rgb, dtype=np.float32)
        return np.einsum("...j,ij->...i", x, self.matrix.astype(np.float32), optimize=False).astype(np.float32)


def _check_chromaticities(chromaticities, path) -> np.ndarray:
    try:
        c = np.array(chromaticities, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        c = None
    if c is None or c.shape != (8,):
        raise InputError(f"chromaticities attribute is malformed ({chromaticities!r}): expected 8 numbers "
                         "(red, green, blue, white x y); refusing to read the file as Rec.709", path)
    if not np.all(np.isfinite(c)):
        raise InputError("chromaticities attribute has non-finite values; refusing to read the file as Rec.709", path)
    xy = c.reshape(4, 2)
    if np.any(xy < -1) or np.any(xy > 2):
        raise InputError(f"chromaticities attribute is not a colour space (xy {xy.round(4).tolist()}: values beyond "
                         "-1..2); refusing to read the file as Rec.709", path)
    # the primaries may be imaginary (ACES2065-1's blue has y -0.077), the white may not: a real
    # chromaticity (x, y, z = 1 - x - y all positive) inside the primaries' triangle, where white
    # is a positive mix of them
    (wx, wy), tri = xy[3], xy[:3]
    if np.any(np.abs(tri[:, 1]) < 1e-9):
        raise InputError(f"chromaticities attribute has a primary with a y of 0 ({tri.round(4).tolist()}): it has no "
                         "finite XYZ; refusing to read the file as Rec.709", path)
    edge, to_white = np.roll(tri, -1, axis=0) - tri, xy[3] - tri
    side = edge[:, 0] * to_white[:, 1] - edge[:, 1] * to_white[:, 0]  # (2-D cross products)
    if abs(edge[0, 0] * edge[1, 1] - edge[0, 1] * edge[1, 0]) < 1e-9:
        return c  # collinear primaries: named as degenerate by working_space_conversion
    if not (wx > 0 and wy > 0 and wx + wy < 1):
        raise InputError(f"chromaticities attribute has a white point ({wx:.4g}, {wy:.4g}) that no colour has (x, y "
                         "and 1 - x - y must be positive); refusing to read the file as Rec.709", path)
    if not (all(v > 0 for v in side) or all(v < 0 for v in side)):
        raise InputError(f"chromaticities attribute has its white point ({wx:.4g}, {wy:.4g}) outside the triangle of "
                         f"its primaries ({tri.round(4).tolist()}); refusing to read the file as Rec.709", path)
    return c


def working_space_conversion(chromaticities, path=None) -> ColourConversion | None:
    """The conversion from a file's RGB space, given by its chromaticities, to the working space.

    Parameters
    ----------
    chromaticities : sequence of 8 float
        Red x y, green x y, blue x y, white x y (CIE 1931), e.g. an EXR ``chromaticities``
        attribute.
    path : path-like, optional
        Named in errors.

    Returns
    -------
    ColourConversion or None
        None when the space is the working space already (within
        :data:`CHROMATICITY_TOLERANCE`).

    Raises
    ------
    InputError
        Malformed values (not 8 finite numbers, beyond -1..2), a white point that is no real
        chromaticity or lies outside the primaries' triangle, or degenerate primaries (collinear:
        no RGB -> XYZ matrix). Imaginary primaries (ACES2065-1's AP0) are converted.
    """
    import colour

    c = _check_chromaticities(chromaticities, path)
    target = colour.RGB_COLOURSPACES["ITU-R BT.709"]
    tgt = np.concatenate([np.asarray(target.primaries).reshape(-1), np.asarray(target.whitepoint)])
    if np.all(np.abs(c - tgt) <= CHROMATICITY_TOLERANCE):
        return None
    primaries, white = c[:6].reshape(3, 2), c[6:]
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")  # degenerate input is judged below, not by a library warning
        try:
            npm = colour.normalised_primary_matrix(primaries, white)
        except (ValueError, np.linalg.LinAlgError, ZeroDivisionError):
            npm = np.full((3, 3), np.nan)
    if not np.all(np.isfinite(npm)) or np.linalg.cond(npm) > _MAX_CONDITION:
        raise InputError(f"chromaticities attribute has degenerate primaries ({primaries.round(4).tolist()}, nearly "
                         "collinear: no RGB to XYZ matrix); refusing to read the file as Rec.709", path)
    src = colour.RGB_Colourspace("file", primaries, white, use_derived_matrix_RGB_to_XYZ=True,
                                 use_derived_matrix_XYZ_to_RGB=True)
    same_white = np.all(np.abs(white - np.asarray(target.whitepoint)) <= CHROMATICITY_TOLERANCE)
    cat = None if same_white else "Bradford"
    M = colour.matrix_RGB_to_RGB(src, target, chromatic_adaptation_transform=cat)
    if not np.all(np.isfinite(M)):
        raise InputError("chromaticities attribute gives a non-finite conversion matrix; refusing to read the file "
                         "as Rec.709", path)
    return ColourConversion(M, _name_of(c), c, cat)


#: Names tried first when naming a file's space (others share these primaries, e.g. ACEScc/ACEScct
#: have ACEScg's AP1; an EXR holds linear values, so the linear space's name is the right one).
_PREFERRED_NAMES = ("ACEScg", "ACES2065-1", "ITU-R BT.2020", "Display P3", "DCI-P3", "Adobe RGB (1998)",
                    "ProPhoto RGB", "ITU-R BT.709")


def _name_of(c: np.ndarray) -> str:
    import colour

    names = [n for n in _PREFERRED_NAMES if n in colour.RGB_COLOURSPACES]
    names += sorted(n for n in colour.RGB_COLOURSPACES.keys() if n not in names)
    for name in names:
        space = colour.RGB_COLOURSPACES[name]
        p = np.asarray(space.primaries, dtype=np.float64).reshape(-1)
        w = np.asarray(space.whitepoint, dtype=np.float64).reshape(-1)
        if p.shape == (6,) and w.shape == (2,) and np.all(np.abs(np.concatenate([p, w]) - c) <= 1e-4):
            return name
    return "custom"


def convert_to_working_space(rgb, chromaticities, path=None) -> tuple[np.ndarray, ColourConversion | None]:
    """``rgb`` (..., 3) in the space of ``chromaticities`` converted to the working space.

    Returns
    -------
    rgb : (..., 3) float32 ndarray
        Converted (the input, as float32, when no conversion is needed).
    conversion : ColourConversion or None
        What was done (None: the space was the working space already).

    Raises
    ------
    InputError
        As :func:`working_space_conversion`.
    """
    conv = working_space_conversion(chromaticities, path)
    if conv is None:
        return np.asarray(rgb, dtype=np.float32), None
    return conv.apply(rgb), conv
