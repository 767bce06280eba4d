"""Per-light weights from a light map: the angular Voronoi diagram of the light directions (Masselus et al. 2002)."""
