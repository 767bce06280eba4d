"""Relighting on the CPU: the weighted sum of the basis photos, basis selection and the compressed basis."""
