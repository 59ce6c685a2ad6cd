"""Skeleton smoothing: the method registry, ``smooth``, the methods themselves and
``LiveSmoother``.

Every method registers itself (:func:`~tobitkf.smoothing.registry.register_method`) in
the module that defines it; :func:`~tobitkf.smoothing.api.smooth`, ``LiveSmoother``, the
command line and the evaluation read the registry. Submodules are imported on demand.
"""
