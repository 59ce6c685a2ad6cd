"""The math core: censored-normal moments, linear-Gaussian models, Kalman and Tobit
filters, the RTS smoother, streaming filters and the censored likelihood.

numpy and scipy only: nothing here imports another part of tobitkf, reads a file or
knows what a skeleton is. Submodules are imported on demand.
"""
