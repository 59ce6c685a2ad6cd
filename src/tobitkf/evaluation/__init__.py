"""Evaluation: time alignment, registration, metrics, joint angles, synthetic benchmark.

Modules (one job each):

- :mod:`~tobitkf.evaluation.pairs`         track joint ↔ mocap point tables (KERAAL, UI-PRMD, CSV)
- :mod:`~tobitkf.evaluation.alignment`     resampling, lag search, mocap offset / rate fit
- :mod:`~tobitkf.evaluation.registration`  robust rigid transform + per-pair offsets
- :mod:`~tobitkf.evaluation.metrics`       RMSE, glitch classes, smoothness M (eq. 41), lag
- :mod:`~tobitkf.evaluation.angles`        elbow / knee angles, RMSE at best and fixed delay
- :mod:`~tobitkf.evaluation.truth`         prepare_truth: mocap → ground truth on the track's frames
- :mod:`~tobitkf.evaluation.scores`        resolve_method, score_estimate, MethodScore
- :mod:`~tobitkf.evaluation.evaluate`      evaluate_methods, evaluate_without_truth, pool_scores
- :mod:`~tobitkf.evaluation.synthetic`     built-in Kinect V2 motion generator, BVH mapping
- :mod:`~tobitkf.evaluation.corruption`    Kinect-like corruption model with glitch labels
- :mod:`~tobitkf.evaluation.benchmark`     run_benchmark: RMSE by glitch type on known truth

Submodules are imported on demand; nothing is imported here.
"""
