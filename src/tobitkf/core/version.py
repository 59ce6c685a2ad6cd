"""The package version, kept in the bottom layer so that every layer can record it
(outputs carry it in their provenance); ``tobitkf.__version__`` is this value and
``pyproject.toml`` holds the same number."""

__version__ = "0.1.0"
