"""OpenCL devices: choosing one, building the programs of ``cl/``, launching kernels by name."""
