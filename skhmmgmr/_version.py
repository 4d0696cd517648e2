"""The package version, in one place (read by setuptools, the JSON format and the report)."""

__version__ = "0.1.0"
