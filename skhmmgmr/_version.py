"""The package version, in one place (read by setuptools, the JSON format and the report)."""

__version__ = "0.2.0.dev0"
