"""Stage 0, files: images, light-map files, ``capture.json`` / ``lights.json`` / RTI ``.lp``, videos.

Formats only: nothing here interprets pixels (that is :mod:`ffls.radiance`). Every reader checks
what it reads and raises :class:`ffls.errors.InputError` naming the file; every writer is atomic.
"""
