"""The end of the pipeline: tone mapping and exposure of relit HDR images for screens and 8-bit files."""
