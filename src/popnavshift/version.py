"""The package's version, declared once: pyproject.toml reads it (``[tool.setuptools.dynamic]``),
the manifest and ``popnavshift --version`` print it."""

__version__ = "0.1.0"
