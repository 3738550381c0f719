"""Type stub of `itt_planner.calibration`: its public names, loaded lazily by `__init__.py`."""

from .aero import AeroFit, AeroSettings, fit_aero
from .calibrate import CalibrationOptions, CalibrationResult, calibrate, rider_yaml, write_rider
from .cornering import CorneringFit, fit_cornering
from .power_curve import CpFit, fit_cp, mmp_curve
from .ride_data import CalibrationError, RideSeries, prepare_ride

__all__ = [
    "AeroFit", "AeroSettings", "CalibrationError", "CalibrationOptions", "CalibrationResult",
    "CorneringFit", "CpFit", "RideSeries", "calibrate", "fit_aero", "fit_cornering", "fit_cp",
    "mmp_curve", "prepare_ride", "rider_yaml", "write_rider",
]
