"""The ground floor: what every layer above may import, and which imports nothing above it.

scikit-learn's private API (``_compat``), shared parameter descriptions (``_docstrings``), the
column schema (``_schema``), recordings as contiguous sequences (``_sequences``) and in a
DataFrame's index (``_panel``), input checks (``_validation``), the one rule for writing output
files (``_files``) and the package version every pickle carries (``_pickled``).
"""
