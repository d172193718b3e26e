"""IMU grades: 1-sigma error tables from named public datasheets (issue 46, item 1).

Each grade is an :class:`~sdr_di.ins.imu.ImuErrorModel` of 1-sigma values (user units:
ppm, mg, deg/h, m/s/sqrt(h), deg/sqrt(h), mrad, deg/h/g, s). The truth (a scenario's
``[imu] grade``) draws a unit from it per seed (:meth:`ImuErrorModel.apply`); a filter's
assumptions (``--assume``, ``[assume.imu] grade``) take its 1-sigma values for ``Q`` and
``P0``. ``docs/assumptions.md`` gives each table with the document every figure comes from
and the tag of each figure; :data:`GRADE_PROVENANCE` holds the same tags:

``D``  read from the document's text in this project (feature list or specification table);
``S``  the document's figure as quoted, with its source, by a secondary reference (NavToolkit's
       ``hg1700_model`` / ``hg9900_model``, which cite the Honeywell brochures as 1-sigma);
``R``  recalled from the document's specification table, not re-read in this project: to be
       checked against the PDF (docs/assumptions.md lists them);
``A``  an assumption where the document gives no figure (reason in docs/assumptions.md).

Sigma convention: a figure in a datasheet's *typical* column is taken as 1-sigma (Bosch
Sensortec and Analog Devices both state that their typical figures are one standard deviation
of the production population); a min/max limit would be 3-sigma (none is used here).
A ``+-x %`` scale-factor tolerance is ``x * 1e4`` ppm; a ``+-x %`` cross-axis sensitivity is a
misalignment of ``x * 10`` mrad; a noise density ``N`` [ug/sqrt(Hz)] is a velocity random
walk ``N * 1e-6 * g * 60`` m/s/sqrt(h), ``N`` [deg/s/sqrt(Hz)] an angle random walk ``N * 60``
deg/sqrt(h).

``mems`` (paper 004 Table 4, the default scenario's IMU) and ``perfect`` are the legacy
presets: the six terms of paper 004 and nothing else, so a scenario using them generates the
same files as before the grades existed.
"""

from __future__ import annotations

from .imu import G_STANDARD, ImuErrorModel

__all__ = ["GRADE_PROVENANCE", "GRADE_SOURCES", "IMU_GRADES", "grade_model"]

_VRW_ICM20948 = 230e-6 * G_STANDARD * 60.0   # 230 ug/sqrt(Hz) -> 0.1353 m/s/sqrt(h)

#: Grade name -> 1-sigma error model (user units; module docstring).
IMU_GRADES: dict[str, ImuErrorModel] = {
    # paper 004 Table 4 (MEMS): the default scenario's IMU
    "mems": ImuErrorModel(100.0, 100.0, 4.0, 8.0, 0.05, 0.04),
    "perfect": ImuErrorModel.perfect(),
    # Honeywell HG9900 (ring-laser gyros, navigation grade)
    "navigation": ImuErrorModel(
        accel_scale_factor_ppm=100.0, gyro_scale_factor_ppm=5.0,
        accel_bias_mg=0.025, gyro_bias_deg_h=0.0035,
        accel_random_walk=0.002, gyro_random_walk=0.002,
        accel_bias_instability_mg=0.010, gyro_bias_instability_deg_h=0.002,
        accel_bias_tau_s=3600.0, gyro_bias_tau_s=3600.0,
        accel_misalignment_mrad=0.02, gyro_misalignment_mrad=0.02,
        gyro_g_sensitivity_deg_h_per_g=0.0),
    # Honeywell HG1700-AG58 (ring-laser gyros, tactical grade)
    "tactical": ImuErrorModel(
        accel_scale_factor_ppm=300.0, gyro_scale_factor_ppm=150.0,
        accel_bias_mg=1.0, gyro_bias_deg_h=1.0,
        accel_random_walk=0.065 * 0.3048, gyro_random_walk=0.125,
        accel_bias_instability_mg=0.05, gyro_bias_instability_deg_h=0.35,
        accel_bias_tau_s=600.0, gyro_bias_tau_s=600.0,
        accel_misalignment_mrad=0.1, gyro_misalignment_mrad=0.1,
        gyro_g_sensitivity_deg_h_per_g=0.0),
    # Analog Devices ADIS16495-1 (MEMS, industrial)
    "industrial": ImuErrorModel(
        accel_scale_factor_ppm=500.0, gyro_scale_factor_ppm=500.0,
        accel_bias_mg=1.0, gyro_bias_deg_h=36.0,
        accel_random_walk=0.008, gyro_random_walk=0.09,
        accel_bias_instability_mg=0.0032, gyro_bias_instability_deg_h=0.8,
        accel_bias_tau_s=300.0, gyro_bias_tau_s=300.0,
        accel_misalignment_mrad=0.873, gyro_misalignment_mrad=0.873,
        gyro_g_sensitivity_deg_h_per_g=32.4),
    # TDK InvenSense ICM-20948 (MEMS, consumer)
    "consumer": ImuErrorModel(
        accel_scale_factor_ppm=5000.0, gyro_scale_factor_ppm=15000.0,
        accel_bias_mg=25.0, gyro_bias_deg_h=5.0 * 3600.0,
        accel_random_walk=_VRW_ICM20948, gyro_random_walk=0.015 * 60.0,
        accel_bias_instability_mg=0.03, gyro_bias_instability_deg_h=10.0,
        accel_bias_tau_s=100.0, gyro_bias_tau_s=100.0,
        accel_misalignment_mrad=20.0, gyro_misalignment_mrad=20.0,
        gyro_g_sensitivity_deg_h_per_g=0.1 * 3600.0),
}

#: Grade name -> the documents its figures come from.
GRADE_SOURCES: dict[str, str] = {
    "mems": "Sun et al., IEEE Access 2020 (paper 004), Table 4",
    "perfect": "no errors",
    "navigation": "Honeywell HG9900 IMU brochure N61-1638-000-000",
    "tactical": "Honeywell HG1700 IMU brochure N61-1619-000-001 (HG1700-AG58)",
    "industrial": "Analog Devices ADIS16495 data sheet Rev. C (ADIS16495-1, +-125 deg/s)",
    "consumer": "TDK InvenSense ICM-20948 data sheet DS-000189 Rev. 1.3",
}

_KEYS = ("accel_scale_factor_ppm", "gyro_scale_factor_ppm", "accel_bias_mg", "gyro_bias_deg_h",
         "accel_random_walk", "gyro_random_walk", "accel_bias_instability_mg",
         "gyro_bias_instability_deg_h", "accel_bias_tau_s", "gyro_bias_tau_s",
         "accel_misalignment_mrad", "gyro_misalignment_mrad", "gyro_g_sensitivity_deg_h_per_g")


def _tags(s: str) -> dict[str, str]:
    return dict(zip(_KEYS, s.split(), strict=True))


#: Grade name -> {term: provenance tag} (module docstring: D, S, R, A), in the order of
#: ``_KEYS``: scale factors (accel, gyro), turn-on biases, random walks, in-run
#: instabilities, correlation times, misalignments, g-sensitivity.
GRADE_PROVENANCE: dict[str, dict[str, str]] = {
    "navigation": _tags("S S S S A S A A A A A A A"),
    "tactical": _tags("A A S S S S A A A A A A A"),
    "industrial": _tags("A A A A R D D D A A D D R"),
    "consumer": _tags("D R D R D R A A A A D R A"),
}


def grade_model(name: str) -> ImuErrorModel:
    """The 1-sigma model of grade ``name``.

    Raises
    ------
    KeyError
        ``name`` is not a grade (callers turn it into their own error naming the key).
    """
    return IMU_GRADES[name]
