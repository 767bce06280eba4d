"""GLSL sources of ffls, one file per pass; shared code in ``include/``.

Installed as ``ffls.shaders``; :func:`ffls.gpu.shaders.load` finds this folder from the package
location, never from the working directory.
"""
from pathlib import Path

SHADER_DIR = Path(__file__).resolve().parent
