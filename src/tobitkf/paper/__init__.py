"""The 2020 paper's experiments: the oscillator (Tables 1-2), the covariance example of
section 3.4 and their figures. Submodules are imported on demand.
"""
