"""Ray tracing in wavelet space (paper §3): the field on the device, quadrature under a tolerance."""
