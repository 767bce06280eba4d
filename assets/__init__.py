"""Bundled assets of ffls (installed as ``ffls.assets``): CC0 light maps by Greg Zaal (Poly Haven)."""
from pathlib import Path

ASSET_DIR = Path(__file__).resolve().parent
LIGHTMAP_DIR = ASSET_DIR / "lightmaps"


def builtin_lightmaps():
    """Return ``{name: path}`` of the bundled lat-long EXR light maps, sorted by name."""
    return {p.stem: p for p in sorted(LIGHTMAP_DIR.glob("*.exr"))}
