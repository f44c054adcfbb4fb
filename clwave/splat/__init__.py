"""Wavelet splatting (paper §4): footprint textures, the tiled device pipeline, progressive frames."""
