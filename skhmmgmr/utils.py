"""Tools for users checking their own configurations: the scikit-learn estimator checks that
an estimator of the package fails by design, and why."""

from .selection._selectors._estimator_checks import expected_failed_checks

__all__ = ["expected_failed_checks"]
