"""Exceptions of the integration-filter layer.

:class:`FilterError` derives from :class:`sdr_di.errors.SdrDiError` (re-exported here) so the
CLI's one-line error handling catches it. It lives in this module until it is added to
:mod:`sdr_di.errors` (the project's single exception module); then this module should
re-export it from there.
"""

from __future__ import annotations

from ..errors import SdrDiError

__all__ = ["SdrDiError", "FilterError", "CovarianceError"]


class FilterError(SdrDiError):
    """Bad filter input or configuration: unknown filter name, wrong-size ``z``/``R``/``Q``,
    non-finite values, non-positive-definite initial covariance, unknown option."""


class CovarianceError(FilterError):
    """A covariance matrix lost positive definiteness during a filter step.

    Attributes
    ----------
    filter_name : str
        Name of the filter (``"UKF"``, ``"ff-aukf"``...).
    step : str
        The step that failed (``"predict"``, ``"update"``).
    matrix : str
        Which matrix (``"P"`` state covariance, ``"S"`` innovation covariance...).
    min_eigenvalue : float
        Smallest eigenvalue of the offending (symmetrized) matrix.
    """

    def __init__(self, filter_name: str, step: str, matrix: str, min_eigenvalue: float,
                 epoch: int | None = None) -> None:
        self.filter_name = filter_name
        self.step = step
        self.matrix = matrix
        self.min_eigenvalue = float(min_eigenvalue)
        self.epoch = epoch
        where = f" at epoch {epoch}" if epoch is not None else ""
        super().__init__(
            f"{filter_name} {step}{where}: covariance {matrix} is not positive definite "
            f"(smallest eigenvalue {min_eigenvalue:.3e}); Cholesky factorization failed. "
            "Check Q/R/P scaling, or construct the filter with psd_fallback='clip' to clip "
            "eigenvalues instead of failing")
