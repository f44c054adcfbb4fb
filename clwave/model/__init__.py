"""The wavelet volume model: volumes, B-spline wavelet bases, the sparse model, transfer functions, cameras."""
