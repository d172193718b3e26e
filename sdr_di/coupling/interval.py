"""What a coupling mode and the integration loop exchange over one filter interval: the
interval (:class:`Interval`), the mode's measurements (:class:`Measurements`), the mode's
interface (:class:`MeasurementSource`) and what it may read of the loop (:class:`LoopState`).

The loop is :class:`sdr_di.integration.loop.IntegrationLoop`; deep mode's source is
:class:`sdr_di.deep.vector_tracking.VectorTracking`, loose's and tight's are in
:mod:`sdr_di.integration`. These types are here, below both, so that deep mode never
imports the integration package that runs it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from ..ins.error_model import NavState

__all__ = ["Interval", "LoopState", "MeasurementSource", "Measurements"]


@dataclasses.dataclass
class Interval:
    """One filter interval: IMU samples ``(i0, i1]``, IF samples ``[k0, k1)``.

    Attributes
    ----------
    i0, i1 : int
        IMU sample indices at the interval's ends.
    k0, k1 : int
        IF sample indices at the interval's ends (the IMU samples' times on the IF clock).
    nav0, nav1 : NavState
        INS at ``i0`` and ``i1`` before the feedback (set by the loop's
        ``propagate_ins``).
    f_mean, w_mean : (3,) arrays
        Bias-compensated averages of the specific force [m/s^2] and angular rate [rad/s],
        body Right-Front-Up, over the interval.
    clock_bias_m : float
        Clock bias predicted to ``k1`` with the drift, before the feedback [m].
    predicted : bool
        The filter's predict over the interval is done (the loop's ``predict_filter``).
    """

    i0: int
    i1: int
    k0: int
    k1: int
    nav0: NavState | None = None
    nav1: NavState | None = None
    f_mean: np.ndarray | None = None
    w_mean: np.ndarray | None = None
    clock_bias_m: float = math.nan
    predicted: bool = False


@dataclasses.dataclass
class Measurements:
    """What a mode measured over one interval (its filter update).

    Attributes
    ----------
    z : (m,) array
        Measurement vector (deep and tight: ``[delta_rho_1..N, delta_rho_dot_1..N]`` [m,
        m/s], paper 004 eq 7-9), or None: no update in this interval (deep: no channel
        usable; loose and tight: no GNSS epoch in it, or none usable).
    R : (m, m) array
        Its noise covariance, or None with ``z``.
    geometry : tuple
        Arguments of the loop's ``set_geometry`` for this update (the filter's measurement
        model at this epoch; deep: the INS position and the lines of sight of ``used``).
    used : (n_ch,) bool array
        Channels in the measurement vector (loose and tight: of the latest GNSS epoch, also
        on the intervals between epochs).
    channels : (n,) int array or None
        PRNs in ``z``'s order (tight; None where not needed).
    columns : (n,) int array or None
        Channel column (index into ``used``) of each channel in ``z``'s order (tight);
        None: ``z`` holds the used channels in column order (deep).
    """

    z: np.ndarray | None
    R: np.ndarray | None
    geometry: tuple
    used: np.ndarray
    channels: np.ndarray | None = None
    columns: np.ndarray | None = None

    @property
    def n_used(self) -> int:
        """Channels in the measurement vector."""
        return int(self.used.sum())


class MeasurementSource(Protocol):
    """A coupling mode's part of the loop (deep: :class:`~sdr_di.deep.vector_tracking.
    VectorTracking`).

    Attributes
    ----------
    n_channels : int
        Channels reported in the rows (``used``, ``cn0``).
    """

    n_channels: int

    def measure(self, loop: LoopState, iv: Interval) -> Measurements | None:
        """Measurements of interval ``iv`` from the propagated INS (``iv.nav1``,
        ``iv.clock_bias_m``); None when the input data ends inside the interval."""

    def feed_back(self, loop: LoopState, iv: Interval, x: np.ndarray) -> None:
        """The mode's share of the closed-loop correction ``x`` (17,) (deep: NCOs and
        pre-filters), after the INS and the clock took theirs."""

    def take_up_navigation_data(self, loop: LoopState, iv: Interval) -> None:
        """Switch to navigation data decoded during ``iv`` (ephemeris, ionosphere)."""

    def row(self) -> dict:
        """The mode's columns of a solution row: ``cn0`` (n_ch,) [dB-Hz] and ``nav``
        (navigation data taken up since the last row, bits 1 ephemeris and 2 ionosphere)."""


class LoopState(Protocol):
    """What a measurement source reads of the integration loop
    (:class:`~sdr_di.integration.loop.IntegrationLoop`).

    Attributes
    ----------
    kf : KalmanFilterBase
        The integration filter (17 states, paper 004 Table 1).
    ins : StrapdownINS
        The INS, corrected by the feedback.
    clock_bias_m : float
        Receiver clock bias at the end of the last interval [m].
    clock_drift_mps : float
        Receiver clock drift [m/s] (loose and tight: read and reset by the source).
    set_geometry : callable
        The filter's measurement model at an epoch, from a ``Measurements.geometry``
        (loose and tight: for the innovation gate's ``S``).
    """

    kf: Any
    ins: Any
    clock_bias_m: float
    clock_drift_mps: float
    set_geometry: Callable[..., None]

    def predict_filter(self, iv: Interval) -> None:
        """The filter's predict over ``iv`` (before its update)."""
