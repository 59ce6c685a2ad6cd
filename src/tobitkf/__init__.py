"""tobitkf: Tobit Kalman filtering of censored measurements, and skeleton-track smoothing.

The public names are imported lazily (PEP 562), so ``import tobitkf`` stays fast and the
command-line tool does not pay for plotting or file-format code it does not use.
"""

from __future__ import annotations

import importlib
from typing import Any

from tobitkf.core.version import __version__

# public name -> module that defines it
_EXPORTS: dict[str, str] = {
    # censored-normal moments (math core)
    "ClippedMoments": "tobitkf.core.censored",
    "clipped_normal_moments": "tobitkf.core.censored",
    "bivariate_normal_cdf": "tobitkf.core.censored",
    "clipped_normal_moments_diag": "tobitkf.core.censored",
    "truncated_standard_normal": "tobitkf.core.censored",
    "TruncatedStats": "tobitkf.core.censored",
    "censored_logpdf": "tobitkf.core.censored",
    # models and filters (math core)
    "LinearGaussian": "tobitkf.core.model",
    "FilterResult": "tobitkf.core.model",
    "SmootherResult": "tobitkf.core.model",
    "kalman_filter": "tobitkf.core.kalman",
    "rts_smooth": "tobitkf.core.kalman",
    "tobit_filter": "tobitkf.core.tobit",
    "adaptive_tobit_filter": "tobitkf.core.tobit",
    "StreamingFilter": "tobitkf.core.streaming",
    # likelihood and fitting
    "censored_loglik": "tobitkf.core.likelihood",
    "fit_noise": "tobitkf.core.likelihood",
    "NoiseFit": "tobitkf.core.likelihood",
    "fit_skeleton_noise": "tobitkf.smoothing.fit",
    "fit_limits": "tobitkf.smoothing.fit",
    "LimitsFit": "tobitkf.smoothing.fit",
    "skeleton_model": "tobitkf.smoothing.paper",
    # skeletons
    "Topology": "tobitkf.skeleton.topology",
    "get_topology": "tobitkf.skeleton.topology",
    "register_topology": "tobitkf.skeleton.topology",
    "available_topologies": "tobitkf.skeleton.topology",
    "SkeletonSequence": "tobitkf.skeleton.sequence",
    "TrackingState": "tobitkf.skeleton.sequence",
    "SampleState": "tobitkf.skeleton.sequence",
    "to_dataframe": "tobitkf.skeleton.dataframe",
    "from_dataframe": "tobitkf.skeleton.dataframe",
    # smoothing and its registry
    "smooth": "tobitkf.smoothing.api",
    "DEFAULT_METHOD": "tobitkf.smoothing.api",
    "DEFAULT_LIVE_METHOD": "tobitkf.smoothing.api",
    "register_method": "tobitkf.smoothing.api",
    "unregister_method": "tobitkf.smoothing.api",
    "methods": "tobitkf.smoothing.api",
    "method_defaults": "tobitkf.smoothing.api",
    "MethodSpec": "tobitkf.smoothing.registry",
    "SmoothInput": "tobitkf.smoothing.registry",
    "SmoothOutput": "tobitkf.smoothing.registry",
    "LiveSmoother": "tobitkf.smoothing.live",
    "DelayedSmoother": "tobitkf.smoothing.delayed",
    "smooth_delayed": "tobitkf.smoothing.delayed",
    "live_methods": "tobitkf.smoothing.live",
    "warmup": "tobitkf.smoothing.warmup",
    # evaluation against ground truth, synthetic benchmark
    "prepare_truth": "tobitkf.evaluation.evaluate",
    "evaluate_methods": "tobitkf.evaluation.evaluate",
    "evaluate_without_truth": "tobitkf.evaluation.evaluate",
    "run_benchmark": "tobitkf.evaluation.benchmark",
    "generate_motion": "tobitkf.evaluation.synthetic",
    "corrupt": "tobitkf.evaluation.corruption",
    # files
    "smooth_files": "tobitkf.app.runner",
    "load": "tobitkf.io",
    "save": "tobitkf.io",
    "detect_format": "tobitkf.io",
    "register_format": "tobitkf.io",
    "formats": "tobitkf.io",
    "ReadError": "tobitkf.io",
    "read_noise_fit": "tobitkf.io.noise_fit",
    "from_movement": "tobitkf.io.movement",
    "to_movement": "tobitkf.io.movement",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'tobitkf' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
