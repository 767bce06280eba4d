"""Light maps: the :class:`LightMap` container, sphere parameterisations with exact solid angles,
light-map files and procedural maps."""
