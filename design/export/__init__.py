"""A design out of Python: C code composed from the law's stages (:mod:`..filters.coefficients.c_export`) and the design
as python-control objects and MATLAB files (:mod:`..filters.coefficients.objects`)."""
