"""Stage 1, radiance: camera response, transfer functions, linearising photos, HDR merging.

Imports only :mod:`ffls.io`, :mod:`ffls.conventions` and :mod:`ffls.errors`.
"""
