"""Calibrate a rider from ride files, and validate the models and plans against rides.

Stage of the data path: recorded rides -> rider parameters (`calibrate`) -> the same rides
replayed through the models and the plan (`validate`). Estimator notes (equations,
assumptions, refusals) are in this package's README.md.
"""

from itt_planner.calibration.aero import AeroFit, AeroSettings, fit_aero
from itt_planner.calibration.calibrate import (
    CalibrationOptions,
    CalibrationResult,
    calibrate,
    rider_yaml,
    write_rider,
)
from itt_planner.calibration.cornering import CorneringFit, fit_cornering
from itt_planner.calibration.power_curve import CpFit, fit_cp, mmp_curve
from itt_planner.calibration.ride_data import CalibrationError, RideSeries, prepare_ride

__all__ = [
    "AeroFit", "AeroSettings", "CalibrationError", "CalibrationOptions", "CalibrationResult",
    "CorneringFit", "CpFit", "RideSeries", "calibrate", "fit_aero", "fit_cornering", "fit_cp",
    "mmp_curve", "prepare_ride", "rider_yaml", "write_rider",
]
